"""bench/team_anatomy.py: sync's merge on the ring2 team taken apart, and two other orders."""

import json

import numpy as np
import pytest
from benchload import load_bench


def _bench():
    return load_bench("team_anatomy")


@pytest.mark.parametrize("seed", [0, 2])
def test_its_sync_order_is_the_rule_and_every_order_is_conflict_free(seed):
    bench = _bench()
    case = bench.multiway.team_case(40, seed=seed)
    rec = bench.anatomy(case)
    assert rec["same_as_sync"] and rec["supported_first"]
    assert all(o["cycle_consistent"] for o in rec["orders"].values())
    assert sum(rec["links"].values()) == len(case.links)
    assert rec["links"]["good_supported"] + rec["links"]["good_unsupported"] == \
        int(np.sum(case.link_good))
    st = rec["stretches"]
    assert 1 <= st["per_landmark_min"] <= st["per_landmark_max"] <= st["count"]


def _two_choices(bench):
    """Cluster X (camera 0) may join Y or Z, which share camera 1: one link to Y, two to Z."""
    mg = bench.Merge(np.array([1, 2, 1, 1]))  # features 0 | 1 2 | 3 | 4
    mg.try_join(1, 3)  # Y: cameras 1, 2
    mg.try_join(2, 4)  # Z: cameras 1, 3
    a, b = np.array([0, 0, 0]), np.array([1, 2, 4])
    return mg, a, b


def test_count_linkage_joins_the_pair_with_more_links():
    bench = _bench()
    mg, a, b = _two_choices(bench)
    bench.count_linkage(mg, a, b, [0, 1, 2])
    np.testing.assert_array_equal(mg.kept(a, b), [False, True, True])


def test_contested_pairs_go_in_order_when_no_other_is_left():
    bench = _bench()
    mg, a, b = _two_choices(bench)
    bench.contested_last(mg, a, b, [0, 1, 2])  # both choices are contested: the first goes
    np.testing.assert_array_equal(mg.kept(a, b), [True, False, False])


def test_an_uncontested_pair_goes_before_a_contested_one():
    bench = _bench()
    m = np.array([2, 1, 1])  # features 0 1 | 2 | 3
    a, b = np.array([0, 1, 3, 2, 0]), np.array([3, 2, 1, 3, 2])
    plain = bench.Merge(m)
    for k in range(5):
        plain.try_join(a[k], b[k])
    # in order: 0-3, then 1-2; the triangle 0-2-3 is split
    np.testing.assert_array_equal(plain.kept(a, b), [True, True, False, False, False])
    mg = bench.Merge(m)
    bench.contested_last(mg, a, b, list(range(5)))
    # 2-3 is the one pair no other choice competes with: it goes first, then 0 joins it
    np.testing.assert_array_equal(mg.kept(a, b), [True, False, False, True, True])


def test_the_stretch_search_swaps_two_stretches_between_clusters():
    bench = _bench()
    # camera 0 holds stretches A1, B1; camera 1 holds A2, B2; A1-A2 and B1-B2 are linked
    # twice, A1-B2 and B1-A2 once; the search starts from the crossed association
    stretch, cam = np.array([0, 1, 2, 3]), np.array([0, 0, 1, 1])
    a, b = np.array([0, 0, 1, 1, 0, 1]), np.array([2, 2, 3, 3, 3, 2])
    crossed = np.array([False] * 4 + [True, True])
    kept = bench.stretch_search(stretch, cam, a, b, crossed)
    # moving A1 to A2's cluster takes B1, which shares A1's camera, the other way
    np.testing.assert_array_equal(kept, [True] * 4 + [False, False])


def test_it_prints_and_saves(tmp_path, capsys):
    out = tmp_path / "out"
    assert _bench().main(["--n", "40", "--seeds", "1", "--out", str(out)]) == 0
    (rec,) = json.loads((out / "results.json").read_text())["records"]
    assert (rec["cameras"], rec["seed"], rec["same_as_sync"]) == (40, 1, True)
    assert sorted(rec["orders"]) == ["contested_last", "count_linkage", "stretch_search", "sync"]
    printed = capsys.readouterr().out
    assert "40 cameras, seed 1:" in printed and "differs" not in printed


def test_a_team_too_small_for_ring2_is_refused(tmp_path, capsys):
    with pytest.raises(SystemExit):
        _bench().main(["--n", "2", "--out", str(tmp_path / "o")])
    assert "--n 2" in capsys.readouterr().err
