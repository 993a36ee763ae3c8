"""``pytest`` run as its console script (not ``python -m pytest``, which puts the checkout on
sys.path itself) imported the test folder ``tests/pipeline`` (no ``__init__.py``) as the
package ``pipeline`` and failed on every test under it; the checkout now comes first on
sys.path (``pythonpath`` in pyproject.toml)."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_the_pytest_script_imports_the_package():
    script = Path(sys.executable).parent / "pytest"
    if not script.exists():
        pytest.skip("no pytest console script beside this Python")
    done = subprocess.run([str(script), "-q", "-p", "no:cacheprovider", "-p", "no:xdist",
                           "tests/pipeline/consistency/test_solve_sets.py",
                           "-k", "scenes_exercise"],
                          cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
