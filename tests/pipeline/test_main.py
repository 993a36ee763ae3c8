"""The command line: cheap top-level help, every command's own help, a run that imports only
what it uses (checked in fresh interpreters through ``sys.modules``, never by timing)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from pipeline.__main__ import COMMANDS, _requested_command, main

ROOT = Path(__file__).resolve().parents[2]
HEAVY = ("cv2", "scipy", "pycolmap", "rerun")


def _imported_after(code: str, env: dict | None = None) -> set[str]:
    """Names in ``sys.modules`` (modules and their top-level packages) after running ``code``
    in a new interpreter."""
    probe = (f"import sys\n{code}\n"
             "import json\nprint(json.dumps(sorted(set(sys.modules)\n"
             "                                  | {m.split('.')[0] for m in sys.modules})))")
    out = subprocess.run([sys.executable, "-c", probe], cwd=ROOT, capture_output=True,
                         text=True, check=True, env={**os.environ, **(env or {})})
    return set(json.loads(out.stdout.strip().splitlines()[-1]))


def test_top_level_help_imports_no_heavy_library():
    code = ("from pipeline.__main__ import main\n"
            "try:\n    main(['--help'])\nexcept SystemExit as e:\n    assert e.code == 0\n")
    loaded = _imported_after(code)
    assert "pipeline" in loaded
    assert not loaded & set(HEAVY), sorted(loaded & set(HEAVY))


def test_python_dash_m_help_lists_every_command():
    out = subprocess.run([sys.executable, "-m", "pipeline", "--help"], cwd=ROOT,
                         capture_output=True, text=True, check=True).stdout
    for name in COMMANDS:
        assert name in out


@pytest.mark.parametrize("command", list(COMMANDS))
def test_each_command_has_its_own_help(command, capsys):
    with pytest.raises(SystemExit) as exc:
        main([command, "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert f"python -m pipeline {command}" in out
    assert "--" in out.split("options:", 1)[1].replace("-h, --help", "")


@pytest.mark.parametrize("argv, command", [
    (["run-formation", "--seed", "3"], "run-formation"),
    (["--help", "run-formation"], None),
    (["bogus"], None),
    ([], None),
])
def test_requested_command(argv, command):
    assert _requested_command(argv) == command


def test_unknown_command_is_an_argparse_error(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["bogus"])
    assert exc.value.code == 2
    assert "invalid choice: 'bogus'" in capsys.readouterr().err


def test_run_without_rerun_or_fusion_imports_neither(tmp_path):
    code = ("from pipeline.run import FormationConfig, run_formation\n"
            f"run_formation(FormationConfig(formation='a', size=(160, 120), max_features=200, "
            f"fusion=False, rerun=False, out={str(tmp_path / 'run')!r}))\n"
            "assert 'pipeline.fusion.voting' not in sys.modules\n")
    loaded = _imported_after(code, {"FORMATION_MATCH_CACHE": str(tmp_path / "cache")})
    assert "pycolmap" in loaded  # the run did triangulate
    assert "rerun" not in loaded
    assert (tmp_path / "run" / "report.json").is_file()


def test_fusion_does_not_import_scipy_stats():
    loaded = _imported_after("import pipeline.fusion.landmarks")
    assert "pipeline.fusion.voting" in loaded
    assert "scipy.stats" not in loaded
