"""The voting benches write to the repository's ``runs/bench-voting`` by default, as the
other benches write to the repository's ``runs/``, whatever the current folder (they wrote
to ``runs/bench-voting`` of the current folder)."""

import argparse
from pathlib import Path

import pytest
from benchload import load_bench

ROOT = Path(__file__).resolve().parents[2]


class _Parsed(Exception):
    pass


@pytest.mark.parametrize("name", ["voting_table1", "voting_fig23", "voting_pipeline"])
def test_the_default_out_is_the_repository_runs(monkeypatch, tmp_path, name):
    monkeypatch.chdir(tmp_path)
    parse = argparse.ArgumentParser.parse_args

    def parsed(self, args=None, namespace=None):  # the options as given, then no work
        raise _Parsed(parse(self, args, namespace))
    monkeypatch.setattr(argparse.ArgumentParser, "parse_args", parsed)
    with pytest.raises(_Parsed) as exc:
        load_bench(name).main.__wrapped__([])
    assert Path(exc.value.args[0].out) == ROOT / "runs" / "bench-voting"
