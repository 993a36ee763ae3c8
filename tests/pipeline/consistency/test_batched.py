"""The batched evaluation (pipeline.consistency.batched) against the per-robot engine, and the
delta messages against whole blocks: same results, rounds, messages and bytes."""

import numpy as np
import pytest
from consistency_graphs import instances, random_instance
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pipeline.consistency import ProtocolOptions, resolve_conflicts
from pipeline.consistency.engine import detect_once
from pipeline.errors import InputError
from pipeline.linkscsv import write_links_csv
from pipeline.run import ledger_from_consistency
from pipeline.transport.simulated import Network, NetworkOptions
from pipeline.types import Links

SETTINGS = settings(max_examples=100, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow,
                                           HealthCheck.function_scoped_fixture])

STATS = ("iterations", "detection_rounds", "resolution_rounds", "messages", "bytes",
         "messages_by_kind", "bytes_by_kind", "max_robot_memory_bytes", "deleted_links",
         "asymmetric_links", "protocol")


def _links_csv(res, path) -> bytes:
    write_links_csv(path, ledger_from_consistency(res))
    return path.read_bytes()


def _same_result(a, b, tmp_path) -> None:
    assert _links_csv(a, tmp_path / "a.csv") == _links_csv(b, tmp_path / "b.csv")
    for f in ("deleted", "reason", "iteration", "round", "case", "component", "track_label"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f)
    for k in STATS:
        assert a.stats[k] == b.stats[k], k
    assert len(a.stats["per_iteration"]) == len(b.stats["per_iteration"])
    for pa, pb in zip(a.stats["per_iteration"], b.stats["per_iteration"], strict=True):
        assert pa.keys() == pb.keys()
        for k in pa:
            np.testing.assert_array_equal(pa[k], pb[k], err_msg=k)


@SETTINGS
@given(inst=instances(max_n=8, max_feat=5), resolution=st.sampled_from(["paper", "evidence"]))
def test_batched_and_per_robot_engines_give_identical_results(inst, resolution, tmp_path):
    fpc, edges, links = inst
    per_robot = resolve_conflicts(fpc, edges, links, resolution=resolution, engine="per-robot")
    batched = resolve_conflicts(fpc, edges, links, resolution=resolution, engine="batched")
    _same_result(per_robot, batched, tmp_path)
    auto = resolve_conflicts(fpc, edges, links, resolution=resolution)
    assert auto.stats["bytes"] == batched.stats["bytes"]


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


@SETTINGS
@given(inst=instances(max_n=7, max_feat=4))
def test_delta_messages_change_traffic_only(inst, tmp_path):
    fpc, edges, links = inst
    whole = resolve_conflicts(fpc, edges, links, protocol=ProtocolOptions(delta_messages=False))
    delta = resolve_conflicts(fpc, edges, links, protocol=ProtocolOptions(delta_messages=True),
                              engine="per-robot")
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
    whole = resolve_conflicts(fpc, None, links, protocol=ProtocolOptions(delta_messages=False))
    delta = resolve_conflicts(fpc, None, links)
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
        resolve_conflicts(fpc, edges, links, opts, engine="batched")
    with pytest.raises(InputError, match="engine 'fast'"):
        resolve_conflicts(fpc, edges, links, engine="fast")
    auto = resolve_conflicts(fpc, edges, links, opts)
    per_robot = resolve_conflicts(fpc, edges, links, opts, engine="per-robot")
    assert auto.stats["messages"] == per_robot.stats["messages"]
    assert auto.stats["protocol"] == "reliable"
    with pytest.raises(InputError, match="delta messages need"):
        resolve_conflicts(fpc, edges, links, opts,
                          protocol=ProtocolOptions(reliable=True, delta_messages=True))
