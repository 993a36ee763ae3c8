"""A Ctrl-C on a bench ends it as it ends the project's commands: one line
``interrupted: bench/NAME.py stopped …`` on stderr and exit status 130, never a traceback or a
death by signal; the previous results stay as they were."""

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from benchload import load_bench

from pipeline.errors import one_line_errors

ROOT = Path(__file__).resolve().parents[2]
#: opencv_floor is no bench of its own: bench/run_formation.py runs it, and its command line is
#: read by hand (its imports count in the floor's time); a Ctrl-C while it loads is checked in
#: test_bench_import_interrupt.py
BENCHES = sorted(p.stem for p in (ROOT / "bench").glob("*.py") if p.stem != "opencv_floor")


@pytest.mark.parametrize("name", BENCHES)
def test_every_bench_main_ends_a_ctrl_c_in_one_line(name):
    main = load_bench(name).main
    assert main.__code__ is one_line_errors(lambda: 0).__code__, f"bench/{name}.py"
    assert "__wrapped__" in vars(main)


def test_a_ctrl_c_during_a_bench_is_one_line_and_130(tmp_path):
    out = tmp_path / "bench"
    out.mkdir()
    (out / "results.json").write_text('{"previous": true}')
    # the bench loaded first (a Ctrl-C while its libraries load is not the question here),
    # then its main, long enough to be interrupted in the middle
    code = ("import sys; sys.path.insert(0, 'tests/bench'); from benchload import load_bench; "
            "main = load_bench('team_moves').main; print('ready', flush=True); "
            f"sys.exit(main(['--n', '3000', '--seeds', '0', '--out', {str(out)!r}]))")
    proc = subprocess.Popen([sys.executable, "-c", code], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline() == "ready\n"
        time.sleep(0.5)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 130
    assert err == "interrupted: bench/team_moves.py stopped, nothing was written or replaced\n"
    assert json.loads((out / "results.json").read_text()) == {"previous": True}
    assert [p.name for p in out.iterdir()] == ["results.json"]
