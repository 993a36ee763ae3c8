"""Robots as threads of one process over the simulated network (for tests and comparisons).

:class:`LocalTeam` gives every robot its own :class:`~pipeline.transport.RoundEndpoint`
on one shared simulated :class:`~pipeline.transport.simulated.Network` (so messages, bytes and the
network's fault switches — drop, crash, delay — are exactly the simulator's). Each message's
drop is decided by the seed, its sender, receiver, round and place among that sender's
messages to that receiver in the round (``Network(keyed_drops=True)``), and inboxes are filled
sender by sender, so a lossy run with a given seed is the same run whatever order the threads
happen to send in. A round closes
when every robot thread has called ``end_round`` (a barrier); robots that have finished or
crashed keep the barrier turning until all are through. Each robot thread runs the same robot
code as a robot process does; only the transport differs.
"""

from __future__ import annotations

import threading

from pipeline.transport import RoundEndpoint
from pipeline.transport.simulated import Network, NetworkOptions

__all__ = ["LocalTeam", "RobotCrashed"]


class RobotCrashed(Exception):
    """Raised inside a robot thread when the simulated network crashes its robot."""


class _LocalEnd(RoundEndpoint):
    def __init__(self, team: LocalTeam, i: int) -> None:
        self.team, self.robot_id = team, int(i)
        self._end = team.network.endpoint(self.robot_id)  # the simulator's Endpoint
        self.neighbours = frozenset(self._end.links_up())
        self.round = 0

    def send(self, dst, kind, payload):
        with self.team._lock:
            self._end.send(int(dst), kind, payload)

    def note_memory(self, nbytes):
        super().note_memory(nbytes)
        with self.team._lock:
            self._end.note_memory(nbytes)

    def end_round(self, state=None):
        team = self.team
        team._states[self.robot_id] = dict(state or {})
        team._barrier.wait()
        net = team.network
        self.round = net.round
        if not net.alive(self.robot_id):
            raise RobotCrashed(self.robot_id)
        states = {k: team._prev_states[k] for k in sorted(self.neighbours)
                  if net.alive(k) and team._prev_states[k] is not None}
        self._last_inbox = list(self._end.inbox())
        return list(self._last_inbox), states

    def counters(self):
        return self.team.network.counters()


class LocalTeam:
    """``n`` robot threads over one simulated :class:`Network`.

    Parameters
    ----------
    n : int
    comm_edges : (E, 2) int
    options : NetworkOptions or None — the simulator's fault switches
    """

    def __init__(self, n: int, comm_edges, options: NetworkOptions | None = None) -> None:
        self.n = int(n)
        # the threads send in whatever order they run: drops keyed by the message, not drawn
        # in send order, so one seed gives one run
        self.network = Network(self.n, comm_edges, options, keyed_drops=True)
        self._lock = threading.Lock()
        self._states: list = [None] * self.n
        self._prev_states: list = [None] * self.n
        self._running = self.n
        self._all_done = False
        self._barrier = threading.Barrier(self.n, action=self._tick)

    def _tick(self) -> None:
        # decided once per round for every thread: all robots are through
        self._all_done = self._running == 0
        self._prev_states = list(self._states)
        self._states = [None] * self.n
        self.network.end_round()

    def run(self, robot_main) -> list:
        """Run ``robot_main(transport) -> result`` in one thread per robot; return the results.

        A crashed robot's result is ``None``; an exception in a robot is re-raised.
        """
        results: list = [None] * self.n
        errors: list = []

        def body(i: int) -> None:
            end = _LocalEnd(self, i)
            try:
                results[i] = robot_main(end)
            except RobotCrashed:
                pass
            except BaseException as exc:  # noqa: BLE001 - re-raised in the caller
                errors.append(exc)
            finally:
                with self._lock:
                    self._running -= 1
                # keep the barrier turning until every robot is through (the last one to
                # finish turns it once more, releasing the others)
                while True:
                    self._barrier.wait()
                    if self._all_done:
                        break

        threads = [threading.Thread(target=body, args=(i,), daemon=True) for i in range(self.n)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        if errors:
            raise errors[0]
        return results
