"""The Makefile's targets as a user types them (dry runs: ``make -n``, nothing is executed)."""

import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.skipif(shutil.which("make") is None, reason="no make on this machine")
@pytest.mark.parametrize("run, arg", [("runs/my run", '"runs/my run"'), ("", "")])
def test_make_view_passes_a_run_path_with_spaces_as_one_argument(run, arg):
    out = subprocess.run(["make", "-n", "-s", "view", f"RUN={run}", "STAMP=Makefile"],
                         cwd=ROOT, capture_output=True, text=True, check=True).stdout
    line = [ln for ln in out.splitlines() if "viz.view" in ln][-1]
    assert line.rstrip().endswith(f"-m viz.view {arg}".rstrip())


@pytest.mark.skipif(shutil.which("make") is None, reason="no make on this machine")
def test_make_bench_runs_every_bench_but_the_floor_that_needs_a_folder():
    # bench/opencv_floor.py takes an image folder (bench/run_formation.py gives it one): run
    # without it, it stopped the full bench with a traceback before the scripts after it
    out = subprocess.run(["make", "-n", "-s", "-o", ".venv/.installed-bench", "bench"],
                         cwd=ROOT, capture_output=True, text=True, check=True).stdout
    listed = next(ln for ln in out.splitlines() if "full bench" in ln).split("set -- ")[1]
    scripts = listed.split(";")[0].split()
    expected = sorted(f"bench/{p.name}" for p in (ROOT / "bench").glob("*.py")
                      if p.name != "opencv_floor.py")
    assert scripts == expected
