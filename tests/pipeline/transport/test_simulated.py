"""The simulated network: neighbours only, next-round delivery, counting, fault switches."""

import numpy as np
import pytest

from pipeline.transport import HEADER_BYTES, NotANeighbourError
from pipeline.transport.simulated import Network, NetworkOptions

EDGES = [[0, 1], [1, 2]]


def payload(k):
    return {"rows": np.arange(k, dtype=np.int32)}


def test_send_only_to_neighbours():
    net = Network(3, EDGES)
    with pytest.raises(NotANeighbourError, match="robot 0 .* robot 2"):
        net.send(0, 2, "blocks", payload(1))


def test_delivery_next_round_and_counters():
    net = Network(3, EDGES)
    net.send(0, 1, "blocks", payload(3))
    net.send(2, 1, "request", payload(1))
    assert net.inbox(1) == [] and net.pending
    net.end_round()
    got = sorted((m.src, m.kind) for m in net.inbox(1))
    assert got == [(0, "blocks"), (2, "request")]
    assert not net.pending
    assert net.messages == 2
    assert net.bytes == 2 * HEADER_BYTES + 4 * 3 + 4 * 1
    assert net.counters()["bytes_by_kind"] == {"blocks": HEADER_BYTES + 12, "request": HEADER_BYTES + 4}
    net.end_round()
    assert net.inbox(1) == []


def test_fault_switches():
    net = Network(3, EDGES, NetworkOptions(delay_rounds=2))
    net.send(0, 1, "blocks", payload(1))
    net.end_round()
    net.end_round()
    assert net.inbox(1) == []
    net.end_round()
    assert len(net.inbox(1)) == 1

    net = Network(3, EDGES, NetworkOptions(drop_probability=1.0))
    net.send(0, 1, "blocks", payload(1))
    net.end_round()
    assert net.inbox(1) == [] and net.dropped == 1 and net.messages == 1

    net = Network(3, EDGES, NetworkOptions(crashed=frozenset({1})))
    assert net.neighbours(0) == frozenset()
    net.send(2, 1, "blocks", payload(1))
    net.end_round()
    assert net.inbox(1) == []

    net = Network(3, EDGES, NetworkOptions(topology=lambda t: EDGES if t == 0 else [[0, 2]]))
    net.send(0, 1, "blocks", payload(1))
    net.end_round()
    with pytest.raises(NotANeighbourError):
        net.send(0, 1, "blocks", payload(1))
    net.send(0, 2, "blocks", payload(1))


def test_crash_at_a_round_and_the_neighbour_table():
    net = Network(3, EDGES, NetworkOptions(crash_at={1: 2}))
    assert net.alive(1) and net.neighbours(0) == frozenset({1})
    net.end_round()
    net.send(0, 1, "blocks", payload(1))  # sent in round 1, due in round 2: 1 is dead by then
    net.end_round()
    assert not net.alive(1) and net.inbox(1) == [] and net.dropped == 1
    assert net.neighbours(0) == frozenset()
    # the neighbour table shows the link, not the crash: robots infer crashes from silence
    assert net.links_up(0) == frozenset({1})
    net.send(0, 1, "blocks", payload(1))
    assert net.dropped == 2 and net.messages == 2


def test_recurrent_topology_every_edge_up_once_per_window():
    from pipeline.transport.simulated import recurrent_topology

    edges = np.array([[0, 1], [1, 2], [2, 3], [0, 3], [0, 2]])
    topo = recurrent_topology(edges, p_up=0.2, window=3, seed=4)
    up = np.array([[tuple(e) in {tuple(x) for x in topo(t).tolist()} for e in edges.tolist()]
                   for t in range(60)])
    assert up.mean() < 0.6  # it does switch
    for w in range(58):
        assert up[w:w + 3].any(axis=0).all()
    np.testing.assert_array_equal(topo(5), topo(5))  # repeatable
    assert topo.window == 3


def test_endpoint_is_a_robots_view_of_the_network():
    net = Network(3, EDGES)
    ep = net.endpoint(1)
    assert ep.links_up() == frozenset({0, 2}) and ep.now == 0
    ep.send(0, "blocks", payload(2))
    with pytest.raises(NotANeighbourError):
        net.endpoint(0).send(2, "blocks", payload(1))
    net.end_round()
    assert [m.src for m in net.endpoint(0).inbox()] == [1] and net.endpoint(0).now == 1
    ep.note_memory(50)
    ep.note_memory(20)
    assert net.peak_memory(1) == 50 and net.peak_memory(0) == 0


def test_graph_per_round_window_and_bulk_counts():
    from pipeline.transport.simulated import recurrent_topology

    static = Network(3, EDGES)
    assert static.edges(7).tolist() == EDGES and static.window == 1
    assert not static.switching and not static.faulty
    topo = recurrent_topology(EDGES, p_up=0.3, window=3, seed=1)
    net = Network(3, EDGES, NetworkOptions(topology=topo))
    assert net.switching and net.faulty and net.window == 3
    assert all(np.array_equal(net.edges(t), topo(t)) for t in range(6))
    net.count("fusion", 4, 100)
    c = net.counters()
    assert c["messages"] == 4 and c["bytes"] == 100 and c["messages_by_kind"] == {"fusion": 4}


def test_delayed_message_to_a_receiver_that_crashes_in_flight_is_lost():
    net = Network(3, EDGES, NetworkOptions(delay_rounds=3, crash_at={1: 2}))
    net.send(0, 1, "blocks", payload(1))  # round 0, due in round 4; robot 1 dies in round 2
    for _ in range(4):
        net.end_round()
        assert net.inbox(1) == []
    assert not net.pending and net.dropped == 1 and net.lost_in_flight == 1


def test_delayed_message_from_a_sender_that_crashes_in_flight_arrives():
    net = Network(3, EDGES, NetworkOptions(delay_rounds=3, crash_at={0: 1}))
    net.send(0, 1, "blocks", payload(1))  # it left in round 0, before the crash
    rounds = 0
    while not net.inbox(1):
        net.end_round()
        rounds += 1
    assert rounds == 4 and not net.alive(0)
    assert net.delivered_after_sender_crash == 1 and net.dropped == 0


def test_delayed_message_over_a_link_that_went_down_in_flight_arrives():
    # the link 0-1 is up in round 0 only: the message left then, it is not recalled
    net = Network(3, EDGES, NetworkOptions(delay_rounds=2,
                                           topology=lambda t: EDGES if t == 0 else [[1, 2]]))
    net.send(0, 1, "blocks", payload(1))
    for _ in range(3):
        net.end_round()
    assert not net.is_neighbour(0, 1) and len(net.inbox(1)) == 1


@pytest.mark.parametrize("options", [NetworkOptions(crashed=frozenset({99})),
                                     NetworkOptions(crash_at={3: 5}),
                                     NetworkOptions(crash_at={-1: 5})])
def test_a_crash_of_a_robot_outside_the_team_is_refused_naming_it(options):
    # it ran the whole stage, then failed with an IndexError while reporting the crashes
    from pipeline.errors import InputError

    with pytest.raises(InputError, match=r"robot (99|3|-1) does not exist; the team's robots "
                                         r"are 0\.\.2"):
        Network(3, EDGES, options)


@pytest.mark.parametrize("options, bad", [
    (dict(delay_rounds=-1), "delay_rounds -1"),  # every message was lost: every link cut
    (dict(delay_rounds=1.5), "delay_rounds 1.5"),
    (dict(drop_probability=-0.5), "drop_probability -0.5"),  # read as no fault at all
    (dict(drop_probability=float("nan")), "drop_probability nan"),
    (dict(drop_probability=2), "drop_probability 2"),
    (dict(seed=-1), "seed -1"),  # numpy's ValueError from inside the generator
    (dict(crash_at={1: -3}), "round -3"),
])
def test_network_options_out_of_range_are_refused_naming_the_value(options, bad):
    from pipeline.errors import InputError

    with pytest.raises(InputError, match=f"NetworkOptions .*{bad}"):
        NetworkOptions(**options)


@pytest.mark.parametrize("edges, needle", [
    ([(0, 9)], r"round 0 gives edge \(0, 9\), which names a robot outside the team's 0\.\.3"),
    ([(0, 1), (-1, 2)], r"round 0 gives edge \(-1, 2\)"),
    (["ab"], r"round 0 gives \['ab'\]; give pairs \(i, j\) of robot ids"),
])
def test_a_topology_that_names_no_robot_of_the_team_is_refused(edges, needle):
    """An edge to robot 9 of 4 ended in an IndexError of the neighbour table; robot -1 was read
    as the last robot."""
    from pipeline.consistency import resolve_conflicts
    from pipeline.errors import InputError
    from pipeline.types import Links

    links = Links([0, 1, 2, 0], [0, 0, 0, 1], [1, 2, 3, 3], [0, 0, 0, 0])
    with pytest.raises(InputError, match=rf"NetworkOptions topology: {needle}"):
        resolve_conflicts([2, 1, 1, 1], None, links, NetworkOptions(topology=lambda t: edges))


def test_a_topology_that_is_no_function_is_refused():
    """NetworkOptions(topology=edges) failed at the first round with "'list' object is not
    callable"."""
    from pipeline.errors import InputError

    with pytest.raises(InputError, match=r"NetworkOptions topology \[\(0, 1\)\]: give a function "
                                         r"of the round"):
        NetworkOptions(topology=[(0, 1)])
    assert NetworkOptions(topology=lambda t: [(0, 1)]).any_fault
