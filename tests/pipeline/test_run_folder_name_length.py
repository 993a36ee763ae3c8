"""A run folder whose own name leaves no room for the names a run keeps beside it
(``.NAME.lock-…``, ``.NAME.tmp-…``, ``.NAME.old-…``) is refused at once, naming the longest
name allowed: a 250-byte --out, a valid folder name, failed with ``.NAME.lock-XXXXXXXX: File
name too long``, a path the user never gave; a 238-byte one ran to its end and failed there
where the file system cannot exchange two folders."""

import json
import os
import sys
from pathlib import Path

import pytest

import pipeline.runfolder as runfolder
from pipeline.__main__ import main

sys.path.insert(0, str(Path(__file__).parent / "commands"))
from hostile import one_line_error  # noqa: E402

#: the longest name beside a run folder NAME is ``.NAME.old-`` and 12 hex digits
RUN_NAME_SPARE = len(".") + len(".old-") + 12


def _limit(folder: Path) -> int:
    return os.pathconf(folder, "PC_NAME_MAX") - RUN_NAME_SPARE


def _never(*a, **k):
    raise AssertionError("a run started although its --out name is too long")


@pytest.mark.parametrize("extra", [0, 1, 12])
def test_a_name_too_long_for_the_names_beside_it_is_refused(tmp_path, capsys, monkeypatch,
                                                            extra):
    import pipeline.runs.formation as batch

    monkeypatch.setattr(batch, "run_formation", _never)
    limit = _limit(tmp_path)
    n = limit + 1 + extra
    out = tmp_path / ("r" * n)
    assert main(["run-formation", "--out", str(out), "--size", "160x120",
                 "--max-features", "150", "--no-rerun"]) == 2
    one_line_error(capsys, f"its name is {n} bytes long",
                   f"may be at most {limit} bytes here", "choose a shorter name")
    assert list(tmp_path.iterdir()) == []


def test_the_longest_name_allowed_is_replaced_without_exchange(tmp_path, monkeypatch):
    """The fallback of two renames keeps the previous run as ``.NAME.old-`` + 12 hex
    digits, the longest of the names beside the folder."""
    monkeypatch.setattr(runfolder, "_exchange", lambda a, b: False)
    out = tmp_path / ("r" * _limit(tmp_path))
    for k in (1, 2):
        with runfolder.atomic_run_folder(out) as d:
            runfolder.write_json_atomic(d / "report.json", {"run": k})
    assert json.loads((out / "report.json").read_text()) == {"run": 2}
    assert [p.name for p in tmp_path.iterdir()] == [out.name]
