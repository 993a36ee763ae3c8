"""A Ctrl-C while a bench run as a program still loads its libraries ends as one in its main:
one line ``interrupted: bench/NAME.py stopped …`` on stderr and exit status 130, no
traceback."""

import os
import subprocess
import sys
from pathlib import Path

import pytest
from benchload import BENCHES, shadowing_package

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def interrupted_numpy(tmp_path_factory):
    """A folder whose ``numpy`` is interrupted while it loads, as by a Ctrl-C then."""
    return shadowing_package(tmp_path_factory.mktemp("interrupted"), "numpy",
                             "raise KeyboardInterrupt\n")


# every bench, opencv_floor too: bench/run_formation.py runs it, and it is run by hand on an
# image folder
@pytest.mark.parametrize("name", BENCHES)
def test_a_ctrl_c_while_a_bench_loads_is_one_line_and_130(name, interrupted_numpy):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(interrupted_numpy), str(ROOT)]))
    # --help: a bench that loaded would print its help and end with 0, doing no work
    proc = subprocess.run([sys.executable, str(ROOT / "bench" / f"{name}.py"), "--help"],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=60)
    assert (proc.returncode, proc.stderr) == (
        130, f"interrupted: bench/{name}.py stopped, nothing was written or replaced\n")
    assert proc.stdout == ""
