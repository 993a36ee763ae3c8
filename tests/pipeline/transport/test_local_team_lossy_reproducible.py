"""A lossy run of robot threads (LocalTeam) is one run per seed: each message's drop is
decided by (seed, sender, receiver, round, its place on that link in the round), not drawn in
the order the threads happen to send, so the lost lists and counters do not change from run
to run."""

import sys
import threading
from pathlib import Path

from pipeline.fusion.robot_loops import run_fusion_reliably
from pipeline.transport.local import LocalTeam
from pipeline.transport.simulated import Network, NetworkOptions

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "fusion"))
from test_robot import _ring_rig, _robots  # noqa: E402


def _run(seed):
    views, feats, links, edges, labels = _ring_rig()
    robots = _robots(views, feats, edges, labels)
    team = LocalTeam(len(views), edges,
                     NetworkOptions(drop_probability=0.2, seed=seed, crash_at={3: 5}))
    outs = team.run(lambda end: run_fusion_reliably(robots[end.id], end))
    c = team.network.counters()
    return ([None if o is None else (o["lost"], o["retransmissions"], o["fusion_rounds"])
             for o in outs], c["messages"], c["dropped"], c["round"])


def test_same_seed_same_lossy_run():
    first = _run(5)
    assert first[2] > 0  # messages were dropped
    for _ in range(4):
        assert _run(5) == first
    assert _run(6) != first


def test_keyed_drops_do_not_depend_on_send_order():
    def dropped(order):
        net = Network(3, [(0, 1), (1, 2), (0, 2)], NetworkOptions(drop_probability=0.5, seed=7),
                      keyed_drops=True)
        seen = []
        for _ in range(20):
            for src, dst in order:
                for k in range(3):
                    net.send(src, dst, "m", {"k": k})
            net.end_round()
            seen.append([(m.src, m.payload["k"]) for i in range(3) for m in net.inbox(i)])
        return seen, net.dropped

    pairs = [(0, 1), (2, 1), (1, 0), (0, 2), (1, 2), (2, 0)]
    a = dropped(pairs)
    assert 0 < a[1] < 20 * 18
    assert dropped(pairs[::-1]) == a
    assert dropped(pairs[2:] + pairs[:2]) == a


def test_threads_sending_in_any_order_drop_the_same_messages():
    # the same sends from racing threads, many times: one outcome
    outcomes = set()
    for _ in range(5):
        net = Network(4, [(0, 1), (1, 2), (2, 3), (3, 0)],
                      NetworkOptions(drop_probability=0.3, seed=11), keyed_drops=True)
        lock = threading.Lock()

        def send(src, net=net, lock=lock):
            for k in range(50):
                with lock:
                    net.send(src, (src + 1) % 4, "m", {"k": k})

        threads = [threading.Thread(target=send, args=(i,)) for i in range(4)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        net.end_round()
        outcomes.add(tuple((m.src, m.payload["k"]) for i in range(4) for m in net.inbox(i)))
    assert len(outcomes) == 1
