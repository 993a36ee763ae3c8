"""bench/images_vs_colmap.py: arguments it cannot run are refused before any work, with one
error line naming them, and the previous results file stays as it was."""

import pytest
from benchload import load_bench

NOTHING = ["--rings-only", "--rings", ""]  # no input: without the checks, a quick empty run


@pytest.mark.parametrize("args, message", [
    (["/nope"], "/nope: no such photo folder"),
    (["--ring-seeds", "x", *NOTHING], "--ring-seeds 'x': expected comma-separated whole"),
    (["--methods", "ours,foo", *NOTHING], "--methods foo: expected a comma-separated subset"),
    (["--inputs", "named,raw", *NOTHING], "--inputs raw: expected a comma-separated subset"),
    (["--rings-only", "--rings", "XYZ"], "--rings XYZ: expected four letters, one facade"),
    (["--rings-only", "--rings", "ABCD,AB1D"], "--rings AB1D: expected four letters"),
    (["--rings-only", "--rings", "ABCD", "--ring-cameras", "18,0"],
     "--ring-cameras 0: a ring needs at least 2 cameras"),
    (["--rings-only", "--rings", "ABCD", "--ring-cameras", "1", "--methods", "ours",
      "--inputs", "named"], "--ring-cameras 1: a ring needs at least 2 cameras"),
    # it ran nothing and saved an empty table over the previous results
    (NOTHING, "nothing to run: --rings-only with no ring"),
])
def test_what_it_cannot_run_is_refused_first(tmp_path, capsys, args, message):
    out = tmp_path / "results.json"
    out.write_text('{"previous": true}')
    with pytest.raises(SystemExit) as exc:
        load_bench("images_vs_colmap").main(args + ["--out", str(out)])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert out.read_text() == '{"previous": true}'


def test_an_out_through_a_file_is_refused_first(tmp_path, capsys):
    (tmp_path / "f").write_text("mine")
    out = tmp_path / "f" / "results.json"
    with pytest.raises(SystemExit) as exc:
        load_bench("images_vs_colmap").main([*NOTHING, "--out", str(out)])
    assert exc.value.code == 2
    assert f"{str(tmp_path / 'f')!r} is a file, not a folder" in capsys.readouterr().err
