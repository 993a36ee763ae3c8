"""bench/multiway.py refuses an unknown formation before any case runs (it ran the labelled
and warped cases first, minutes of work, then refused it)."""

from benchload import load_bench


def test_an_unknown_formation_is_refused_before_any_case(tmp_path, capsys, monkeypatch):
    bench = load_bench("multiway")

    def no_case(*args, **kwargs):
        raise AssertionError("a case ran before --formations was checked")
    for name in ("landmark_case", "warped_landmarks", "graffiti_case", "team_case"):
        monkeypatch.setattr(bench, name, no_case)
    out = tmp_path / "bench"
    assert bench.main(["--data", str(tmp_path), "--formations", "z", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: unknown formation 'z'; choose one of") and "\n" == err[-1]
    assert not out.exists()


