"""run-formations holds its four run folders from the start, as run-formation holds its --out:
a formation folder that another run is writing is refused before any formation runs (it was
refused when run-formations reached it, after minutes of work on the others, all lost)."""

import subprocess
import sys

import pipeline.runs.formation
from pipeline.__main__ import main

_HOLD = ("import sys, time\nfrom pipeline.runfolder import claim_run_folder\n"
         "with claim_run_folder(sys.argv[1]):\n print('held', flush=True)\n time.sleep(30)")


def _no_formation_runs(*args, **kwargs):
    raise AssertionError("a formation ran although one of the run folders is busy")


def test_a_busy_formation_folder_is_refused_before_any_work(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("FORMATION_MATCH_CACHE", "off")
    out = tmp_path / "runs"
    out.mkdir()
    holder = subprocess.Popen([sys.executable, "-c", _HOLD, str(out / "formation-c")],
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        monkeypatch.setattr(pipeline.runs.formation, "run_formation", _no_formation_runs)
        assert main(["run-formations", "-q", "--size", "64x48", "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert "formation-c" in err and f"being written by another run (pid {holder.pid})" in err
    finally:
        holder.kill()
        holder.wait()
    # nothing of this command left (the killed holder's lock is removed by the next run)
    assert sorted(p.name for p in out.iterdir()) == [".formation-c.lock"]
