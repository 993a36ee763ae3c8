"""The voting benches write to the repository's ``runs/bench-voting`` by default, as the
other benches write to the repository's ``runs/``, whatever the current folder (they wrote
to ``runs/bench-voting`` of the current folder)."""

from pathlib import Path

import pytest
from benchload import default_options

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("name", ["voting_table1", "voting_fig23", "voting_pipeline"])
def test_the_default_out_is_the_repository_runs(monkeypatch, tmp_path, name):
    monkeypatch.chdir(tmp_path)
    assert Path(default_options(monkeypatch, name).out) == ROOT / "runs" / "bench-voting"
