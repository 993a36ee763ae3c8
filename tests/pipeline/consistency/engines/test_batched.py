"""The batched evaluation (pipeline.consistency.engines.batched, .batched_evidence) against the per-robot
engine, and the delta messages against whole blocks: same results, rounds, messages and bytes."""

from unittest.mock import patch

import numpy as np
import pytest
from consistency_graphs import instances, random_instance
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from pipeline.commgraph import comm_edges_for
from pipeline.consistency import (
    ProtocolOptions,
    evidence,
    resolve_conflicts,
)
from pipeline.consistency.engines import (
    batched,
    batched_evidence,
    batched_resolution,
    sync_batched,
)
from pipeline.consistency.engines.driver import (
    _equip_evidence,
    build_robots,
    detect_once,
)
from pipeline.consistency.engines.phases import run_phase
from pipeline.consistency.protocols import DETECTION, RESOLUTION, make_protocol
from pipeline.errors import InputError
from pipeline.inputs.linkscsv import write_links_csv
from pipeline.stages import ledger_from_consistency
from pipeline.transport.simulated import Network, NetworkOptions
from pipeline.types import Links

SETTINGS = settings(max_examples=100, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow,
                                           HealthCheck.function_scoped_fixture])

STATS = ("iterations", "detection_rounds", "resolution_rounds", "messages", "bytes",
         "messages_by_kind", "bytes_by_kind", "max_robot_memory_bytes", "deleted_links",
         "asymmetric_links", "protocol", "large_sets", "bundle_budget")


def _links_csv(res, path) -> bytes:
    write_links_csv(path, ledger_from_consistency(res))
    return path.read_bytes()


def _same_result(a, b, tmp_path) -> None:
    assert _links_csv(a, tmp_path / "a.csv") == _links_csv(b, tmp_path / "b.csv")
    for f in ("deleted", "reason", "iteration", "round", "case", "component", "track_label"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f)
    for k in STATS:
        assert a.stats.get(k) == b.stats.get(k), k
    assert len(a.stats["per_iteration"]) == len(b.stats["per_iteration"])
    for pa, pb in zip(a.stats["per_iteration"], b.stats["per_iteration"], strict=True):
        assert pa.keys() == pb.keys()
        for k in pa:
            np.testing.assert_array_equal(pa[k], pb[k], err_msg=k)


def _poses(fpc, which: str, seed: int):
    """Keypoints and projections of every robot: none, all, or some poses known."""
    if which == "none":
        return None, None
    rng = np.random.default_rng(seed)
    keypoints = [rng.uniform(0, 100, size=(m, 2)).astype(np.float32) for m in fpc]
    K = np.array([[100.0, 0, 50], [0, 100.0, 50], [0, 0, 1]])
    projections = [None if which == "some" and rng.random() < 0.3 else
                   K @ np.c_[np.eye(3), rng.normal(0, 0.1, 3) + [0, 0, 5]] for _ in fpc]
    return keypoints, projections


def _no_fallback(*args, **kwargs):
    raise AssertionError("the batched pass fell back to robot by robot")


@SETTINGS
@given(inst=instances(max_n=8, max_feat=5), resolution=st.sampled_from(["paper", "evidence"]),
       poses=st.sampled_from(["none", "all", "some"]), seed=st.integers(0, 2**32 - 1),
       budget=st.sampled_from([None, 1, 2, 4]))
def test_batched_and_per_robot_engines_give_identical_results(inst, resolution, poses, seed,
                                                              budget, tmp_path):
    fpc, edges, links = inst
    kp, P = _poses(fpc, poses, seed)
    kw = dict(resolution=resolution, keypoints=kp, projections=P)
    if resolution == "evidence":  # small budgets: some sets large, solved by the merge
        kw["bundle_budget"] = budget
    per_robot = resolve_conflicts(fpc, edges, links, engine="per-robot", **kw)
    with patch.object(batched_evidence, "run_robot_by_robot", _no_fallback), \
            patch.object(batched_resolution, "_run_stepped", _no_fallback), \
            patch.object(sync_batched, "run_sync", _no_fallback):
        in_batch = resolve_conflicts(fpc, edges, links, engine="batched", **kw)
    _same_result(per_robot, in_batch, tmp_path)
    auto = resolve_conflicts(fpc, edges, links, **kw)
    assert auto.stats["bytes"] == in_batch.stats["bytes"]


def _evidence_pass(inst, poses, seed, run_pass):
    """One detection, then one evidence pass by ``run_pass`` where it found a conflictive set:
    the robots, the network and the pass's result (``None`` without a set)."""
    fpc, edges, links = inst
    robots, link_index = build_robots(fpc, links)
    network = Network(len(fpc), comm_edges_for(fpc, links, edges))
    det = batched.run_detection(robots, network, make_protocol(None, network, fpc), 1)
    kp, P = _poses(fpc, poses, seed)
    _equip_evidence(robots, link_index, links, None, kp, P)
    out = run_pass(robots, network) if det["conflictive_features"] else None
    return robots, network, out


@SETTINGS
@given(inst=instances(max_n=9, max_feat=6), poses=st.sampled_from(["none", "all", "some"]),
       seed=st.integers(0, 2**32 - 1), chunk=st.sampled_from([1, 5, 1 << 20]))
def test_batched_evidence_pass_leaves_every_robot_in_the_per_robot_state(inst, poses, seed,
                                                                        chunk):
    # chunk: the groups flooded side by side in one round's arrays (1: one group a chunk)
    ra, na, oa = _evidence_pass(inst, poses, seed, evidence.run_evidence_resolution)
    assume(oa is not None)  # a pass without a conflictive set compares untouched robots
    with patch.object(batched_evidence, "run_robot_by_robot", _no_fallback), \
            patch.object(batched_evidence, "CHUNK_FORWARDS", chunk):
        rb_, nb, ob = _evidence_pass(inst, poses, seed, batched_evidence.run_evidence_resolution)
    assert oa == ob  # rounds, sets, robots in sets
    assert na.counters() == nb.counters()  # messages and bytes by kind, the clock
    _same_robots(ra, rb_)


def _same_robots(ra, rb_) -> None:
    """Two runs' robots hold the same links, deletion logs, memory and evidence state."""
    for a, b in zip(ra, rb_, strict=True):
        for f in ("link_alive", "deleted_round", "deleted_case", "deleted_iteration",
                  "candidates"):
            np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f)
        assert a.peak_memory_bytes == b.peak_memory_bytes
        assert a.evidence.held_bytes == b.evidence.held_bytes
        assert a.evidence.solved == b.evidence.solved
        assert set(a.evidence.bundles) == set(b.evidence.bundles)


@SETTINGS
@given(inst=instances(max_n=9, max_feat=6), poses=st.sampled_from(["none", "all", "some"]),
       seed=st.integers(0, 2**32 - 1))
def test_batched_set_problems_are_each_sets_own(inst, poses, seed):
    # every set's links, cameras and weights (triangle support included, three-view tested
    # where the set's poses are known) computed for all sets at once are those
    # evidence.set_problem computes from the set's bundles
    robots, _, _ = _evidence_pass(inst, poses, seed, lambda robots, network: None)
    links = [evidence.own_set_links(rb) for rb in robots]
    pb = batched_evidence._SetProblems(robots, links)
    by_label: dict = {}
    for rb in robots:
        for label, (_, _, bundles) in evidence.own_sets(rb).items():
            by_label.setdefault(label, {}).update(bundles)
    assume(by_label)  # without a conflictive set there is no problem to compare
    assert pb.label.tolist() == sorted(by_label)
    for label, bundles in by_label.items():
        bundles = dict(sorted(bundles.items()))
        want = evidence.set_problem(bundles)
        e = pb.of(label)
        w = pb.weight(e, *evidence.set_geometry(bundles))
        for got, exp in zip((pb.a[e], pb.b[e], pb.cam_a[e], pb.cam_b[e], w), want[:5],
                            strict=True):
            np.testing.assert_array_equal(got, exp)


def test_batched_evidence_pass_on_a_long_cycle_matches_robot_by_robot():
    # one conflictive set around a cycle of 40 robots: every robot receives every bundle
    n = 40
    links = Links(list(range(n - 1)) + [0], [0] * (n - 1) + [1], list(range(1, n)) + [n - 1],
                  [0] * n, np.linspace(0.2, 0.9, n))
    fpc = np.ones(n, dtype=np.int64)
    fpc[0] = 2
    inst = (fpc, None, links)
    ra, na, oa = _evidence_pass(inst, "all", 0, evidence.run_evidence_resolution)
    with patch.object(batched_evidence, "run_robot_by_robot", _no_fallback):
        rb_, nb, ob = _evidence_pass(inst, "all", 0, batched_evidence.run_evidence_resolution)
    assert oa == ob and oa["rounds"] == n // 2 + 1
    assert na.counters() == nb.counters()
    assert [r.peak_memory_bytes for r in ra] == [r.peak_memory_bytes for r in rb_]
    assert [r.deleted_round.tolist() for r in ra] == [r.deleted_round.tolist() for r in rb_]


def test_batched_evidence_falls_back_where_a_set_graph_is_not_symmetric():
    # a robot has cut its side of its links to a neighbour that still holds them: the flood
    # is not the one the batched evaluation covers, so the pass runs robot by robot, and
    # ends as the robot-by-robot pass does on the same state
    fpc, edges, links = random_instance(np.random.default_rng(5), 5, 4, 1.0, 1.0)
    inst = (fpc, edges, links)
    calls = []

    def count_fallback(*args, **kwargs):
        calls.append(1)
        return evidence.run_evidence_resolution(*args, **kwargs)

    def cut_one_end(run_pass):
        def run(robots, network):
            rb = next(r for r in robots if (r.link_alive & r.conflictive[r.link_r]).any())
            rows = rb.link_alive & rb.conflictive[rb.link_r]
            j = rb.link_nbr[np.flatnonzero(rows)[0]]
            rb.link_alive[rows & (rb.link_nbr == j)] = False  # robot j still lists rb
            return run_pass(robots, network)
        return run

    with patch.object(batched_evidence, "run_robot_by_robot", count_fallback):
        rb_, nb, ob = _evidence_pass(inst, "none", 0,
                                     cut_one_end(batched_evidence.run_evidence_resolution))
    assert calls == [1]
    ra, na, oa = _evidence_pass(inst, "none", 0, cut_one_end(evidence.run_evidence_resolution))
    assert ob == oa == {"rounds": 3, "conflictive_sets": 1, "robots_in_sets": 5}
    assert na.counters() == nb.counters()
    _same_robots(ra, rb_)
    assert sum(rb.evidence.solved == {0} for rb in rb_) == 5  # every robot solved the set


@SETTINGS
@given(inst=instances(max_n=8, max_feat=5))
def test_batched_detection_leaves_every_robot_in_the_per_robot_state(inst):
    fpc, edges, links = inst
    a = detect_once(fpc, links, network=Network(len(fpc), edges), engine="per-robot")
    b = detect_once(fpc, links, network=Network(len(fpc), edges), engine="batched")
    assert a.stats["rounds"] == b.stats["rounds"]
    np.testing.assert_array_equal(a.stats["t_stop"], b.stats["t_stop"])
    assert a.network.counters() == b.network.counters()
    for ra, rb in zip(a.robots, b.robots, strict=True):
        assert (ra.X != rb.X).nnz == 0 and ra.X.shape == rb.X.shape
        for f in ("conflictive", "set_label", "track_label", "active"):
            np.testing.assert_array_equal(getattr(ra, f), getattr(rb, f), err_msg=f)
        assert ra.root_of_set == rb.root_of_set
        assert (ra.stopped, ra.t_stop, ra.peak_memory_bytes) == \
            (rb.stopped, rb.t_stop, rb.peak_memory_bytes)
        assert ra.memory_bytes() == rb.memory_bytes()


def _detect_on(robots, network, engine: str) -> dict:
    proto = make_protocol(None, network, robots[0].offsets[1:] - robots[0].offsets[:-1])
    if engine == "batched":
        return batched.run_detection(robots, network, proto, 1)
    return run_phase(robots, network, proto, DETECTION, iteration=1)


@SETTINGS
@given(inst=instances(max_n=8, max_feat=5), seed=st.integers(0, 2**32 - 1),
       p_cut=st.sampled_from([0.0, 0.3, 1.0]), dense_max=st.sampled_from([0, 1 << 24]))
def test_batched_detection_matches_per_robot_on_links_alive_at_one_end(inst, seed, p_cut,
                                                                      dense_max):
    # some robots have cut their side of some links whose other end still holds them: the
    # tables are not symmetric, P is not, and the batched detection takes the general path
    # (X as sorted keys, dense_max 0, or as a dense array)
    fpc, edges, links = inst
    runs = []
    for engine in ("per-robot", "batched"):
        robots, _ = build_robots(fpc, links)
        rng = np.random.default_rng(seed)
        for rb in robots:
            rb.link_alive &= rng.random(rb.link_alive.size) >= p_cut * 0.5
        network = Network(len(fpc), comm_edges_for(fpc, links, edges))
        with patch.object(batched, "DENSE_KEYS_MAX", dense_max):
            runs.append((robots, network, _detect_on(robots, network, engine)))
    (ra, na, sa), (rb_, nb, sb) = runs
    if p_cut == 0.0 and len(links):
        assert batched._Team(rb_).symmetric
    assert sa["rounds"] == sb["rounds"] and na.counters() == nb.counters()
    np.testing.assert_array_equal(sa["t_stop"], sb["t_stop"])
    for a, b in zip(ra, rb_, strict=True):
        assert (a.X != b.X).nnz == 0
        for f in ("conflictive", "set_label", "track_label"):
            np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f)
        assert a.root_of_set == b.root_of_set
        assert a.peak_memory_bytes == b.peak_memory_bytes


def test_batched_detection_takes_the_general_path_on_a_link_alive_at_one_end():
    fpc = np.array([1, 1, 1])
    links = Links([0, 1], [0, 0], [1, 2], [0, 0])
    robots, _ = build_robots(fpc, links)
    for rb in robots:
        rb.active[:] = True
    assert batched._Team(robots).symmetric
    robots[1].link_alive[robots[1].link_nbr == 2] = False  # robot 2 still lists its side
    assert not batched._Team(robots).symmetric


@SETTINGS
@given(inst=instances(max_n=8, max_feat=5))
def test_batched_resolution_leaves_every_robot_in_the_per_robot_state(inst):
    fpc, edges, links = inst
    runs = []
    for engine in ("per-robot", "batched"):
        det = detect_once(fpc, links, network=Network(len(fpc), edges), engine="per-robot")
        if engine == "per-robot":
            stats = run_phase(det.robots, det.network, det.protocol, RESOLUTION, iteration=1)
        else:
            with patch.object(batched_resolution, "_run_stepped", _no_fallback):
                stats = batched.run_resolution(det.robots, det.network, det.protocol, 1)
        runs.append((det, stats))
    (a, sa), (b, sb) = runs
    assert sa == sb
    assert a.network.counters() == b.network.counters()
    for i in range(len(fpc)):
        assert a.network.peak_memory(i) == b.network.peak_memory(i)
    for ra, rb in zip(a.robots, b.robots, strict=True):
        for f in ("component", "assigned_round", "link_alive", "deleted_round", "deleted_case",
                  "deleted_iteration", "candidates"):
            np.testing.assert_array_equal(getattr(ra, f), getattr(rb, f), err_msg=f)
        assert ra.peak_memory_bytes == rb.peak_memory_bytes


def test_batched_resolution_settles_contention_in_the_receivers_order():
    """Robot 0 roots one set with two features (two components); each reaches robot 3's one
    feature in round 2, through robots 1 and 2: the receiver's order (component, sender
    robot, sender feature) lets the first join and cuts the other (b), as robot by robot."""
    fpc = np.array([2, 1, 1, 1])
    links = Links(np.array([0, 0, 1, 2]), np.array([0, 1, 0, 0]), np.array([1, 2, 3, 3]),
                  np.array([0, 0, 0, 0]), np.ones(4))
    edges = comm_edges_for(fpc, links, None)
    settled = []

    def counting(q, r, outcome, cand):
        settled.append(cand.size)
        return settle(q, r, outcome, cand)

    settle = batched_resolution.settle_contention
    res = {}
    for engine in ("per-robot", "batched"):
        with patch.object(batched_resolution, "_run_stepped", _no_fallback), \
                patch.object(batched_resolution, "settle_contention", counting):
            res[engine] = resolve_conflicts(fpc, edges, links, engine=engine, resolution="paper")
    assert settled == [2]  # the batched round met the contention
    a, b = res["per-robot"], res["batched"]
    assert a.case.tolist() == ["", "", "", "b"]
    for f in ("deleted", "case", "round", "component"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f)
    assert a.stats["bytes_by_kind"] == b.stats["bytes_by_kind"]


@SETTINGS
@given(inst=instances(max_n=7, max_feat=4))
def test_delta_messages_change_traffic_only(inst, tmp_path):
    fpc, edges, links = inst
    whole = resolve_conflicts(fpc, edges, links, protocol=ProtocolOptions(delta_messages=False),
                              resolution="paper")
    delta = resolve_conflicts(fpc, edges, links, protocol=ProtocolOptions(delta_messages=True),
                              engine="per-robot", resolution="paper")
    for f in ("deleted", "reason", "iteration", "round", "case", "component", "track_label"):
        np.testing.assert_array_equal(getattr(whole, f), getattr(delta, f), err_msg=f)
    assert whole.stats["detection_rounds"] == delta.stats["detection_rounds"]
    assert delta.stats["bytes"] <= whole.stats["bytes"]
    assert delta.stats["messages"] <= whole.stats["messages"]


def test_delta_messages_cut_the_bytes_of_a_long_chain():
    # a chain of 30 robots, one feature each: a row grows by at most two entries per round;
    # whole blocks resend everything, a delta message carries at most those two entries
    n = 30
    links = Links(np.arange(n - 1), np.zeros(n - 1, int), np.arange(1, n), np.zeros(n - 1, int))
    fpc = np.ones(n, dtype=np.int64)
    whole = resolve_conflicts(fpc, None, links, protocol=ProtocolOptions(delta_messages=False),
                              resolution="paper")
    delta = resolve_conflicts(fpc, None, links, resolution="paper")
    assert whole.stats["detection_rounds"] == delta.stats["detection_rounds"] == n
    blocks_w = whole.stats["bytes_by_kind"]["blocks"]
    blocks_d = delta.stats["bytes_by_kind"]["blocks"]
    # header 12 + rows (1 int32) + indptr (2 int32) + at most 2 indices (int32)
    assert blocks_d <= (12 + 4 + 8 + 8) * delta.stats["messages_by_kind"]["blocks"]
    assert blocks_d < blocks_w / 2


def test_auto_engine_is_per_robot_under_faults_and_batched_cannot_be_forced_there():
    fpc, edges, links = random_instance(np.random.default_rng(3), 6, 4, 0.6, 0.8)
    opts = NetworkOptions(drop_probability=0.2, seed=1)
    with pytest.raises(InputError, match="engine 'batched' needs"):
        resolve_conflicts(fpc, edges, links, opts, engine="batched", resolution="paper")
    with pytest.raises(InputError, match="engine 'fast'"):
        resolve_conflicts(fpc, edges, links, engine="fast", resolution="paper")
    auto = resolve_conflicts(fpc, edges, links, opts, resolution="paper")
    per_robot = resolve_conflicts(fpc, edges, links, opts, engine="per-robot", resolution="paper")
    assert auto.stats["messages"] == per_robot.stats["messages"]
    assert auto.stats["protocol"] == "reliable"
    with pytest.raises(InputError, match="delta messages need"):
        resolve_conflicts(fpc, edges, links, opts,
                          protocol=ProtocolOptions(reliable=True, delta_messages=True),
                          resolution="paper")
