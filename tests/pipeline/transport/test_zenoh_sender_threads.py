"""A robot's threads do not grow with its neighbours (pipeline.transport.zenoh_transport,
"Threads"): at most SENDER_THREADS senders, each neighbour always served by the same one, and
one subscriber per key kind; every neighbour still gets its packets, in order."""

import threading
from collections import defaultdict

from pipeline.team.launcher import make_team
from pipeline.transport.zenoh_transport import SENDER_THREADS, ZenohTransport

LEAVES = SENDER_THREADS + 4  # some senders serve two neighbours
ROUNDS = 4


def _join(threads, errors):
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert not errors, errors


def test_a_robot_with_many_neighbours_runs_few_threads_and_delivers_in_order():
    n = LEAVES + 1
    team = make_team("senders", [[0, i] for i in range(1, n)],
                     {"kind": "links", "links": "in.csv", "features_per_camera": [1] * n}, n=n)
    before = threading.active_count()
    centre = ZenohTransport(team, 0, round_timeout_s=30.0, log=lambda s: None)
    robots = [centre] + [None] * LEAVES
    try:
        # senders, the beat thread and one callback thread per subscriber (six key kinds),
        # where one sender and six subscribers per neighbour made 7 x LEAVES + 1
        assert len(centre._senders) == SENDER_THREADS
        assert threading.active_count() - before <= SENDER_THREADS + 1 + 6
        assert len(centre._subs) == 6

        errors = []

        def open_leaf(i):
            try:
                robots[i] = ZenohTransport(team, i, round_timeout_s=30.0, log=lambda s: None)
            except Exception as exc:  # noqa: BLE001 - reported by _join
                errors.append(exc)

        _join([threading.Thread(target=open_leaf, args=(i,)) for i in range(1, n)], errors)

        # the centre's puts, per neighbour: the packet's round and the thread that put it
        puts = defaultdict(list)
        for k in range(1, n):
            put = centre._pubs[k].put

            def record(data, k=k, put=put):
                from pipeline.transport.wire import decode_packet

                puts[k].append((decode_packet(data)[0]["round"], threading.get_ident()))
                return put(data)

            centre._pubs[k] = type("Pub", (), {"put": staticmethod(record)})()

        got = defaultdict(list)

        def run(i):
            try:
                rb = robots[i]
                rb.handshake(timeout_s=30.0)
                for r in range(ROUNDS):
                    for k in sorted(rb.neighbours):
                        rb.send(k, "x", {"r": r, "src": i})
                    inbox, _ = rb.end_round()
                    got[i].append(sorted((m.src, m.payload["r"]) for m in inbox))
            except Exception as exc:  # noqa: BLE001 - reported by _join
                errors.append(exc)

        _join([threading.Thread(target=run, args=(i,)) for i in range(n)], errors)
        assert got[0] == [[(k, r) for k in range(1, n)] for r in range(ROUNDS)]
        for i in range(1, n):
            assert got[i] == [[(0, r)] for r in range(ROUNDS)], i
        assert sorted(puts) == list(range(1, n))
        for k, seq in puts.items():
            assert [r for r, _ in seq] == list(range(ROUNDS)), k  # in order, each once
            assert len({t for _, t in seq}) == 1, k  # always the same sender
        assert len({t for seq in puts.values() for _, t in seq}) == SENDER_THREADS
        assert not any(rb.written_off for rb in robots)
        assert centre.counters()["send_s"] >= 0.0 and centre.wire_packets == LEAVES * ROUNDS
    finally:
        for rb in robots:
            if rb is not None:
                rb.close()
