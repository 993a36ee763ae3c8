"""viz.saved_run holds the run folder while it reads it and writes its recording there: a run
replacing the folder meanwhile (another command into the same --out) got the previous run's
recording added to its own folder, listed in its marker as its own."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

from test_rerun_log import make_record
from test_saved_run import _save

import viz.rerun_log
from pipeline.outputs import run_folder_problem
from pipeline.runfolder import atomic_run_folder
from viz.saved_run import log_run_folder

_REPLACE = """
import shutil, sys
from pathlib import Path
from pipeline.errors import InputError
from pipeline.runfolder import atomic_run_folder
try:
    with atomic_run_folder(sys.argv[1]) as tmp:
        for p in Path(sys.argv[2]).iterdir():
            (shutil.copytree if p.is_dir() else shutil.copy)(p, tmp / p.name)
except InputError as exc:
    print(exc)
    sys.exit(2)
"""


def _run_folder(path, record, tag):
    with atomic_run_folder(path) as staged:
        _save(record, staged / "x")
        for p in (staged / "x").iterdir():
            p.rename(staged / p.name)
        (staged / "x").rmdir()
        report = json.loads((staged / "report.json").read_text())
        (staged / "report.json").write_text(json.dumps({**report, "tag": tag}))
    return path


def test_a_run_into_the_folder_while_its_recording_is_made_is_refused(tmp_path, monkeypatch):
    record = make_record()
    run = _run_folder(tmp_path / "run", record, "first")
    other = _run_folder(tmp_path / "other", record, "second")
    shutil.move(other / ".formation-match-run", tmp_path / "other-marker")
    tried = []
    log_run = viz.rerun_log.log_run

    def replaced_meanwhile(out, rec, **kw):
        tried.append(subprocess.run([sys.executable, "-c", _REPLACE, str(run), str(other)],
                                    capture_output=True, text=True))
        return log_run(out, rec, **kw)

    monkeypatch.setattr(viz.rerun_log, "log_run", replaced_meanwhile)
    log_run_folder(run)
    assert tried[0].returncode == 2, tried[0].stderr
    assert "is being written by another run" in tried[0].stdout
    assert json.loads((run / "report.json").read_text())["tag"] == "first"
    assert (run / "recording.rrd").is_file() and run_folder_problem(run) is None


def test_a_folder_being_written_is_not_read(tmp_path, capsys):
    from pipeline.runfolder import claim_run_folder
    from viz.saved_run import main

    run = _run_folder(tmp_path / "run", make_record(), "first")
    holder = subprocess.Popen([sys.executable, "-c", (
        "import sys, time\nfrom pipeline.runfolder import claim_run_folder\n"
        "with claim_run_folder(sys.argv[1]):\n print('held', flush=True)\n time.sleep(30)")
        , str(run)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        assert main([str(run)]) == 2
        err = capsys.readouterr().err
        assert f"pid {holder.pid}" in err and "wait for it to finish" in err
        assert not (run / "recording.rrd").exists()
    finally:
        holder.kill()
        holder.wait()
    with claim_run_folder(run):  # the lock is free again: nothing left behind
        pass
