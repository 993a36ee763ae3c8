"""bench/fusion.py checks --size, --formations and --resolutions before its first case: a size
that is no WIDTHxHEIGHT ended in a ValueError traceback, and a bad formation or rule after it
the cases listed before it had run (each a rendering, matching and fusion, minutes at 640x480)."""

import pytest
from benchload import load_bench


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
    out = tmp_path / "bench"
    out.mkdir()
    (out / "results.json").write_text('{"previous": true}')
    try:
        code = bench.main([*args, "--no-sceaux", "--repeat", "1", "--out", str(out)])
    except SystemExit as exc:
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert (out / "results.json").read_text() == '{"previous": true}'
