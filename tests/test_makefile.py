"""The Makefile's targets as a user types them (dry runs: ``make -n``, nothing is executed)."""

import shlex
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.skipif(shutil.which("make") is None, reason="no make on this machine")
@pytest.mark.parametrize("run", ["runs/my run", "", "runs/it's", 'runs/a "b"', "runs/$HOME",
                                 "runs/$(x) `y` \\z"])
def test_make_view_passes_a_run_path_as_one_argument_as_typed(run):
    # a '$' was read by make ('runs/$HOME' became 'runs/OME'), a '"' or '`' by the shell
    out = subprocess.run(["make", "-n", "-s", "-o", ".venv/.installed", "view", f"RUN={run}"],
                         cwd=ROOT, capture_output=True, text=True, check=True).stdout
    line = [ln for ln in out.splitlines() if "viz.view" in ln][-1]
    args = shlex.split(line)
    assert args[args.index("viz.view") + 1:] == ([run] if run else [])


@pytest.mark.skipif(shutil.which("make") is None, reason="no make on this machine")
def test_the_dry_run_of_make_view_leaves_the_makefile_of_a_tree_without_venv(tmp_path):
    # the test above passed STAMP=Makefile to keep make from setting up: in a tree whose .venv
    # is not its own (none, or one made for another folder), the Makefile's check removes the
    # stamp, $(STAMP), at parse time, and so deleted the tracked Makefile
    for name in ("Makefile", "pyproject.toml"):
        shutil.copy(ROOT / name, tmp_path / name)
    out = subprocess.run(["make", "-n", "-s", "-o", ".venv/.installed", "view", "RUN=runs/x"],
                         cwd=tmp_path, capture_output=True, text=True, check=True).stdout
    assert "viz.view runs/x" in out.replace("'", "")
    assert (tmp_path / "Makefile").read_text() == (ROOT / "Makefile").read_text()


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


OLD_PYTHON = """#!/bin/sh
case "$1" in
  --version) echo "Python 3.10.12" ;;
  -c) exit 1 ;;
  -m) mkdir -p "$3/bin" && cp "$0" "$3/bin/python" ;;
esac
"""


#: a pyenv shim of a version that is installed but not selected: a command that does not run
SHIM_PYTHON = """#!/bin/sh
echo "pyenv: python3.10: command not found" >&2
exit 127
"""


@pytest.mark.skipif(shutil.which("make") is None, reason="no make on this machine")
@pytest.mark.parametrize("python, said", [
    ("no-such-python-3", "is not a command"),
    ("", "is not a command"),
    ("OLD", "is Python 3.10.12"),
    # was named "is pyenv: python3.10: command not found", as if a Python too old
    ("SHIM", "does not run (exit 127: pyenv: python3.10: command not found)")])
def test_make_setup_names_a_python_it_cannot_use_before_making_the_venv(tmp_path, python, said):
    # a PYTHON that is not a command, or older than 3.11, made a .venv (or a shell error,
    # '-m: not found'), then asked for make clean before the right PYTHON was taken
    for name in ("Makefile", "pyproject.toml"):
        shutil.copy(ROOT / name, tmp_path / name)
    if python in ("OLD", "SHIM"):
        (tmp_path / "python3.10").write_text(OLD_PYTHON if python == "OLD" else SHIM_PYTHON)
        (tmp_path / "python3.10").chmod(0o755)
        python = str(tmp_path / "python3.10")
    run = subprocess.run(["make", "setup", f"PYTHON={python}"], cwd=tmp_path,
                         capture_output=True, text=True)
    assert run.returncode != 0
    assert f"error: PYTHON='{python}' {said}" in run.stderr
    assert "3.11 or newer" in run.stderr
    assert not (tmp_path / ".venv").exists()


@pytest.mark.skipif(shutil.which("make") is None, reason="no make on this machine")
@pytest.mark.parametrize("imports_from, remade", [("other", True), ("clone", False)])
def test_a_venv_made_for_another_folder_is_made_again(tmp_path, imports_from, remade):
    # a clone moved (or copied) after make setup kept its .venv, whose editable install and
    # .venv/bin/formation-match name the old folder ('exec: …/old/.venv/bin/python: not found')
    import sys

    clone = tmp_path / "clone"
    for folder in (clone, tmp_path / "other"):
        (folder / "pipeline").mkdir(parents=True)
        (folder / "pipeline" / "__init__.py").write_text("")
    for name in ("Makefile", "pyproject.toml"):
        shutil.copy(ROOT / name, clone / name)
    python = clone / ".venv" / "bin" / "python"  # a venv importing pipeline from imports_from
    python.parent.mkdir(parents=True)
    python.write_text(f'#!/bin/sh\nPYTHONPATH="{tmp_path / imports_from}" '
                      f'exec "{sys.executable}" "$@"\n')
    python.chmod(0o755)
    (clone / ".venv" / ".installed").touch()
    out = subprocess.run(["make", "-n", "-s", "setup"], cwd=clone, capture_output=True,
                         text=True, check=True).stdout
    assert ("pip install" in out) == remade
    assert (clone / ".venv" / ".installed").exists() != remade
