"""Paper Fig. 1: robots A, B, C, D = 0, 1, 2, 3; the chain f2^D-f1^A-f1^B-f1^C-f1^D."""

import numpy as np

from pipeline.association import AssociationGraph, count_conflicts
from pipeline.commgraph import comm_edges_for
from pipeline.consistency import resolve_conflicts
from pipeline.consistency.engines.driver import detect_once
from pipeline.transport.simulated import Network
from pipeline.types import Links

FPC = [1, 1, 1, 2]


def fig1_links():
    return Links(cam_i=[0, 0, 1, 2], feat_i=[0, 0, 0, 0], cam_j=[3, 1, 2, 3], feat_j=[1, 0, 0, 0])


def test_fig1_detected_by_the_robots_whose_features_it_involves():
    links = fig1_links()
    once = detect_once(FPC, links)
    robots, det = once.robots, once.stats
    # every robot holds a feature of the set, so every robot finds it (rules 8 and 9)
    for rb in robots:
        assert rb.conflictive.all(), rb.id
        # each robot knows all five features of the set: global ids 0..4
        row = rb.X[0].indices
        assert sorted(row.tolist()) == [0, 1, 2, 3, 4]
        # root by eq. (10): D holds two features of the set
        assert rb.root_of_set == {0: 3}
    # D sees its own two features joined (rule 8); A sees two features of D (rule 9)
    assert robots[3].X[0, 4] and robots[3].X[1, 3]
    # diameter of the chain is 4: every robot stops within d + 1 = 5 rounds (Cor. 3.6)
    assert det["t_stop"].max() <= 5
    assert det["t_stop"][3] == 5


def test_fig1_resolution_cuts_the_conflict():
    links = fig1_links()
    res = resolve_conflicts(FPC, None, links, resolution="paper")
    assert res.deleted.sum() >= 1
    assert count_conflicts(AssociationGraph(FPC, res.kept())).conflictive_sets == 0
    # the root D opens one component per own feature: C_3 = {f1^D, ...}, C_4 = {f2^D, ...}
    assert res.component[3] == 3 and res.component[4] == 4
    for q in (3, 4):
        members = np.flatnonzero(res.component == q)
        cams = np.searchsorted(np.cumsum(FPC), members, side="right")
        assert members.size >= 2 and np.unique(cams).size == members.size
    # requests for C_3 (via C) and C_4 (via A) meet at B in round 2; sorted by component id,
    # B joins C_3 and rejects C_4: link A-B is cut with case (b)
    assert res.deleted.tolist() == [False, True, False, False]
    assert res.case[1] == "b" and res.round[1] == 2 and res.iteration[1] == 1
    assert res.reason[1] == "resolution" and res.reason[0] == ""
    assert res.stats["asymmetric_links"] == 0
    assert res.stats["messages"] > 0 and res.stats["bytes"] > 0


def test_fig1_with_explicit_comm_graph_including_an_idle_edge():
    res = resolve_conflicts(FPC, [[0, 1], [1, 2], [2, 3], [0, 3], [0, 2]], fig1_links(),
                            resolution="paper")
    assert res.deleted.sum() == 1


def test_stopped_robot_stays_silent_and_neighbours_use_its_last_blocks():
    links = fig1_links()
    net = Network(4, comm_edges_for(FPC, links))
    sent = []
    send = net.send

    def spy(src, dst, kind, payload):
        sent.append((net.round, src, dst, kind))
        send(src, dst, kind, payload)

    net.send = spy
    once = detect_once(FPC, links, network=net, engine="per-robot")  # robots send one by one
    robots, t_stop = once.robots, once.stats["t_stop"]
    assert sent
    assert t_stop[1] < t_stop[3]  # B stops before D
    for rnd, src, _, kind in sent:
        assert kind == "blocks" and rnd < t_stop[src]  # nothing after Prop. 3.5 fires
    # A and C kept running after B went silent and still know the whole set
    assert t_stop[0] > t_stop[1] and t_stop[2] > t_stop[1]
    assert robots[0].X[0].nnz == 5 and robots[2].X[0].nnz == 5


def test_link_between_non_neighbours_is_an_input_error():
    import pytest

    from pipeline.errors import InputError

    with pytest.raises(InputError, match=r"link 0 \(0,0\)-\(3,1\) joins cameras 0 and 3, which are not neighbours"):
        resolve_conflicts(FPC, [[0, 1], [1, 2], [2, 3]], fig1_links(), resolution="paper")
    with pytest.raises(InputError, match="own neighbour"):
        resolve_conflicts(FPC, [[0, 0]], fig1_links(), resolution="paper")
