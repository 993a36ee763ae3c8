"""bench/sync_weights.py: the support of ``sync`` scaled by alpha, merged centrally."""

import json

import numpy as np
import pytest
from benchload import load_bench


def _bench():
    return load_bench("sync_weights")


@pytest.mark.parametrize("seed", [0, 3])
def test_alpha_one_is_sync_and_zero_is_the_quality_order(seed):
    bench = _bench()
    from pipeline.consistency import resolve_conflicts
    from pipeline.matching.link_evidence import ratio_llr

    case = bench.multiway.team_case(40, seed=seed)
    w, _ = bench.multiway.sync_evidence(case.m, case.links)
    sync = ~resolve_conflicts(case.m, case.edges, case.links, resolution="sync").deleted
    np.testing.assert_array_equal(bench.greedy_merge(case.m, case.links, w), sync)
    # alpha 0: the merge follows the ratio log-odds alone; every kept link is conflict-free
    lam = ratio_llr(1.0 - case.links.quality)
    kept = bench.greedy_merge(case.m, case.links, lam)
    assert case.scores(kept)["cycle_consistent"]
    assert not np.array_equal(kept, sync)  # on the team the quality is noise: it differs


def test_it_prints_and_saves_each_input(tmp_path, capsys):
    out = tmp_path / "out"
    assert _bench().main(["--frames", "--warped-seeds", "--team", "40", "--team-seeds", "1",
                          "--alphas", "0", "2", "--out", str(out)]) == 0
    saved = json.loads((out / "results.json").read_text())
    (rec,) = saved["records"]
    assert (rec["cameras"], rec["team_seed"], rec["same_as_sync"]) == (40, 1, True)
    assert sorted(rec["alphas"]) == ["0", "1", "2"]  # alpha 1 (sync) always measured
    assert rec["good_links_f1"] == pytest.approx(1.0, abs=1e-12)
    printed = capsys.readouterr().out
    assert "team 40, seed 1" in printed and "differs" not in printed
    obj = rec["objective"]
    case = _bench().multiway.team_case(40, seed=1)
    assert obj["separated"]["truth"] == int((~np.asarray(case.link_good, bool)).sum())
    # the search starts from sync's association and only makes moves that join at least as
    # many input links: it never separates more than sync
    assert obj["separated"]["stretch_search"] <= obj["separated"]["sync"]
    assert 0.0 <= obj["stretch_search_f1"] <= 1.0
    assert f"{obj['separated']['truth']} / {obj['separated']['sync']} / " in printed


def test_the_objective_check_counts_what_each_association_separates():
    bench = _bench()
    case = bench.multiway.team_case(40, seed=0)
    w, _ = bench.multiway.sync_evidence(case.m, case.links)
    from pipeline.matching.link_evidence import ratio_llr

    lam = ratio_llr(1.0 - case.links.quality)
    obj = bench.objective_check(case, w, lam)
    sync = bench.greedy_merge(case.m, case.links, w)
    good = np.asarray(case.link_good, bool)
    assert obj["separated"]["sync"] == int((~sync).sum())
    assert obj["w_joined"]["truth"] == pytest.approx(float(w[good].sum()), rel=1e-12)
    assert obj["w_joined"]["sync"] == pytest.approx(float(w[sync].sum()), rel=1e-12)


def test_a_negative_alpha_is_refused(tmp_path, capsys):
    with pytest.raises(SystemExit):
        _bench().main(["--team", "40", "--frames", "--warped-seeds", "--alphas", "-1",
                       "--out", str(tmp_path / "o")])
    assert "--alphas -1" in capsys.readouterr().err


def test_the_search_starts_from_syncs_association_when_a_strong_link_blocks_a_supported_one():
    """A wrong link given the strongest descriptor evidence is merged first and blocks
    supported links: ``sync`` cuts links that close triangles, so the stretches of the
    supported links alone would join links ``sync`` cut; the search's atoms must not."""
    bench = _bench()
    case = bench.multiway.team_case(40, seed=0)
    w, _ = bench.multiway.sync_evidence(case.m, case.links)
    from pipeline.matching.link_evidence import ratio_llr

    lam = ratio_llr(1.0 - case.links.quality)
    good = np.asarray(case.link_good, bool)
    wrong = np.flatnonzero(~good & (w - lam <= 0))
    assert len(wrong)
    w, lam = w.copy(), lam.copy()
    w[wrong[:3]] += 1000.0
    lam[wrong[:3]] += 1000.0
    sync = bench.greedy_merge(case.m, case.links, w)
    assert (~sync & (w - lam > 0)).any()  # a supported link cut: the case this test is for
    obj = bench.objective_check(case, w, lam)
    assert obj["start_is_sync"]
    assert obj["separated"]["stretch_search"] <= obj["separated"]["sync"]
