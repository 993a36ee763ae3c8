"""bench/multiway.py refuses an unknown formation before any case runs (it ran the labelled
and warped cases first, minutes of work, then refused it); its check of each distributed rule
against the best centralized baseline of the same input."""

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




def _row(method, f1, **kw):
    base = dict(case="warped", data="hotel", frames=30, graph="seq:4", inputs="sift descriptors",
                warp_seed=4, hidden=0.0, status="ok")
    return {**base, **kw, "method": method, "f1": f1}


def test_the_baseline_check_compares_each_rule_with_the_best_baseline_as_printed():
    bench = load_bench("multiway")
    records = [
        _row("sync", 0.685), _row("evidence", 0.81519), _row("quality_merge", 0.8152),
        _row("spectral_sync", 0.301), _row("clear", 0.177),
        # another input: sync above; a renumbered copy and a failed row take no part
        _row("sync", 0.95, graph="ring2"), _row("spectral_sync", 0.90, graph="ring2"),
        _row("sync", 0.10, graph="ring2", renumber=1),
        _row("quality_merge", 0.99, graph="ring2", status="out of memory"),
        # an input without any centralized baseline is not checked
        _row("sync", 0.5, graph="complete"),
    ]
    checks = bench.baseline_check(records)
    got = {(c["method"], c["graph"]): (c["verdict"], c["best_baseline"]) for c in checks}
    # evidence 0.81519 is below 0.8152 but prints as it: equal, as a reader of the tables sees
    assert got == {("sync", "seq:4"): ("below", "quality_merge"),
                   ("evidence", "seq:4"): ("equal", "quality_merge"),
                   ("sync", "ring2"): ("above", "spectral_sync")}
    lines = bench.baseline_lines(checks)
    assert any(line.startswith("  sync, warped (sift descriptors): above on 1, equal on 0, "
                               "below on 1 of 2; largest shortfall -0.1302") for line in lines)
