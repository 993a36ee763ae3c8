import json

import pytest

from pipeline.runfolder import atomic_run_folder, write_json_atomic


def test_failed_run_keeps_previous(tmp_path):
    out = tmp_path / "runs" / "demo"
    with atomic_run_folder(out) as d:
        write_json_atomic(d / "report.json", {"run": 1})
    with pytest.raises(RuntimeError):
        with atomic_run_folder(out) as d:
            write_json_atomic(d / "report.json", {"run": 2})
            raise RuntimeError("stage failed")
    assert json.loads((out / "report.json").read_text()) == {"run": 1}
    assert sorted(p.name for p in out.parent.iterdir()) == ["demo"]


def test_second_run_replaces_first(tmp_path):
    out = tmp_path / "demo"
    for k in (1, 2):
        with atomic_run_folder(out) as d:
            write_json_atomic(d / "report.json", {"run": k})
    assert json.loads((out / "report.json").read_text()) == {"run": 2}


def test_outputs_are_readable_like_plain_files(tmp_path):
    import os

    mask = os.umask(0o022)
    try:
        with atomic_run_folder(tmp_path / "demo") as d:
            write_json_atomic(d / "report.json", {})
    finally:
        os.umask(mask)
    assert oct((tmp_path / "demo").stat().st_mode & 0o777) == oct(0o755)
    assert oct((tmp_path / "demo" / "report.json").stat().st_mode & 0o777) == oct(0o644)
