"""The random instances of the property tests: valid inputs, and most of them hold a conflict
(an instance without one tests only the empty case)."""

import numpy as np
from consistency_graphs import conflictive_sets, instances, plant_conflicts, random_instance
from hypothesis import HealthCheck, given, settings

from pipeline.association import check_links
from pipeline.types import Links

EXAMPLES = 200


def test_most_instances_hold_a_conflictive_set():
    drawn = []

    @settings(max_examples=EXAMPLES, deadline=None, database=None,
              suppress_health_check=[HealthCheck.too_slow])
    @given(instances())
    def draw(inst):
        fpc, edges, links = inst
        check_links(links, fpc)  # Assumptions 2.1-2.3
        pairs = {tuple(e) for e in np.asarray(edges).tolist()}
        assert set(zip(links.cam_i.tolist(), links.cam_j.tolist(), strict=True)) <= pairs
        drawn.append((len(links), conflictive_sets(fpc, links)))

    draw()
    n_links, n_sets = np.array(drawn).T
    assert len(drawn) >= EXAMPLES // 2
    assert (n_sets > 0).mean() >= 0.6, f"{(n_sets > 0).sum()} of {len(drawn)} with a conflict"
    assert (n_links == 0).mean() <= 0.1, f"{(n_links == 0).sum()} of {len(drawn)} without links"
    assert (n_sets == 0).sum() >= 5  # conflict-free inputs are still drawn
    assert (n_sets >= 2).sum() >= 5  # and inputs with several sets


def test_a_planted_chain_joins_two_features_of_one_camera():
    # no link at all: each chain makes one conflictive set of its own or joins another
    fpc, edges, links = plant_conflicts(np.random.default_rng(0), [1, 1, 1, 1, 1],
                                        np.zeros((0, 2)), Links([], [], [], []), 1)
    check_links(links, fpc)
    assert conflictive_sets(fpc, links) == 1
    assert 3 <= len(links) <= 5  # a chain through 2..4 other cameras, closed
    assert (np.bincount(np.r_[links.cam_i, links.cam_j], minlength=5) % 2 == 0).all()
    # planted over random links, with existing matches followed: still valid
    for seed in range(30):
        fpc, edges, links = random_instance(np.random.default_rng(seed), 6, 4, 0.6, 1.0)
        before = conflictive_sets(fpc, links)
        fpc, edges, links = plant_conflicts(np.random.default_rng(seed), fpc, edges, links, 2)
        check_links(links, fpc)
        assert conflictive_sets(fpc, links) >= min(before, 1)


def test_conflictive_sets_by_hand():
    # paper Fig. 1: 0:0 - 1:0 - 2:0 - 3:0 - 0:1, one set holding camera 0 twice
    links = Links([0, 1, 2, 0], [0, 0, 0, 1], [1, 2, 3, 3], [0, 0, 0, 0])
    assert conflictive_sets([2, 1, 1, 1], links) == 1
    assert conflictive_sets([2, 1, 1, 1], links.subset(np.array([0, 1, 2]))) == 0
    # two separate triangles, each closing on two features of camera 0
    links = Links([0, 1, 0, 0, 1, 0], [0, 0, 1, 2, 1, 3], [1, 2, 2, 1, 2, 2], [0, 0, 0, 1, 1, 1])
    assert conflictive_sets([4, 2, 2], links) == 2
