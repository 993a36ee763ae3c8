"""Every bench runs on the pipeline of its own checkout, from any current folder: run as
``python bench/NAME.py`` (or by its full path from elsewhere) it puts the repository's root
first on ``sys.path``, so that another ``pipeline`` on the path (another checkout's, an
installed one) is not the one it measures."""

import os
import subprocess
import sys
from pathlib import Path

import pytest
from benchload import BENCHES, shadowing_package

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def other_pipeline(tmp_path_factory):
    """A folder whose ``pipeline`` is not this checkout's."""
    return shadowing_package(tmp_path_factory.mktemp("other"), "pipeline",
                             "raise ImportError('the pipeline of another checkout')\n")


@pytest.mark.parametrize("name", BENCHES)
def test_a_bench_runs_its_own_checkouts_pipeline_from_any_folder(name, other_pipeline, tmp_path):
    env = dict(os.environ, PYTHONPATH=str(other_pipeline))
    proc = subprocess.run([sys.executable, str(ROOT / "bench" / f"{name}.py"), "--help"],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert (proc.returncode, proc.stderr) == (0, ""), proc.stderr
    assert "usage" in proc.stdout
