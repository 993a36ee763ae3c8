"""bench/fusion.py checks --size, --formations and --resolutions before its first case: a size
that is no WIDTHxHEIGHT ended in a ValueError traceback, and a bad formation or rule after it
the cases listed before it had run (each a rendering, matching and fusion, minutes at 640x480)."""

import pytest
from benchload import load_bench, previous_results, refused


@pytest.mark.parametrize("args, message", [
    (["--size", "foo"], "argument --size: --size 'foo': expected WIDTHxHEIGHT, e.g. 640x480"),
    (["--size", "10x10"], "argument --size: --size '10x10': at least 64x48 pixels"),
    (["--formations", "a", "z"], "error: unknown formation 'z'; choose one of"),
    (["--formations", "a", "--resolutions", "evidence", "foo"],
     "error: resolution 'foo': choose one of paper, evidence"),
])
def test_fusion_refuses_before_its_first_case(tmp_path, capsys, monkeypatch, args, message):
    bench = load_bench("fusion")

    def no_case(*a, **k):
        raise AssertionError("a case ran before the refusal")
    monkeypatch.setattr(bench, "_formation_inputs", no_case)
    monkeypatch.setattr(bench, "_sceaux_inputs", no_case)
    out = previous_results(tmp_path)
    err = refused(bench.main, [*args, "--no-sceaux", "--repeat", "1", "--out", str(out)], out,
                  capsys)
    assert message in err
