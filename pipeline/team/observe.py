"""A standalone observer of a team whose robots were started elsewhere (by hand, on several
machines): ``formation-match observe --team TEAM.json --out DIR``.

It opens a Zenoh session listening on the team file's ``observer`` endpoint (every robot
connects to it besides its neighbours of lower id, :mod:`pipeline.transport.zenoh_transport`), and
collects what the one-machine launcher's observer collects
(:class:`pipeline.team.launcher.Observer`): each robot's published result (acknowledged, so
the robot stops repeating it) and its statuses. It takes no part in the algorithm and never
relays between robots. The run folder is then made from the results exactly as the launcher's
run makes it (:mod:`pipeline.team.assemble`, the ``zenoh`` transport's job functions), so a
team started by hand ends in the same ``links.csv`` as ``--transport zenoh``.

When it stops (every wait is bounded)
    It waits until every robot of the team has ended: published its result, published a
    ``failed: ...`` status (a :class:`~pipeline.errors.TeamError` naming it), or vanished
    without a result (its Zenoh liveliness token deleted — its process ended — and no
    result within :data:`GRACE_S` after that: a lost robot, reported as killed), or never
    started and was written off by every neighbour in their published results (it can no
    longer take part: lost too, without waiting for ``timeout_s``). A robot
    not ended within ``timeout_s`` of the observer's start is lost too; if no robot at all
    published by then, a TeamError names one that never started.

    It then stays up to :data:`SETTLE_S` more (never past ``timeout_s``), acknowledging the
    repeats of every robot that still repeats its result: a receipt can be lost with the link
    it went on (a robot's link to an observer paused longer than the observer's lease, e.g.
    by SIGSTOP, is closed by the robot and opened again; the results queued on the old link
    still arrive, their receipts do not), and a robot that never hears one repeats its result
    for ``start_timeout_s``. A robot has stopped repeating when its liveliness token is gone
    and no result came from it for :data:`QUIET_S`.

A robot restarted with the same id
    A robot's process says ``started`` once, as its session opens. A token that vanished and
    came back *without* a new ``started`` is a link that lapsed (the robot ran on); one that
    vanished before a ``started`` came again is a new process of that robot, the first one
    having ended without a result (killed, crashed). Its neighbours wrote the first one off
    and cut its links, and a robot written off is never taken back, so the robot is lost:
    reported among the killed at its first vanish, named in a log line, and whatever the new
    process publishes is acknowledged (so it stops repeating it) but not used.
"""

from __future__ import annotations

import time

from pipeline.errors import InputError, TeamError
from pipeline.team.launcher import Observer, TeamRun
from pipeline.transport.wire import WireError, decode_packet

__all__ = ["observe_team", "TeamObserver", "GRACE_S", "unreported"]

#: seconds a robot whose liveliness token vanished has to deliver its result (it publishes
#: before closing its session; this covers the packet still in flight)
GRACE_S = 2.0

#: longest the observer stays, once it has every result, for robots still repeating theirs
SETTLE_S = 5.0

#: seconds without a result from a robot whose token is gone after which it has stopped
#: repeating (a robot repeats every 0.25 s; a link opened again after a lapse takes longer)
QUIET_S = 1.0


class TeamObserver(Observer):
    """:class:`~pipeline.team.launcher.Observer` that also hears robots' liveliness tokens
    vanish (a robot process that ended)."""

    def __init__(self, team) -> None:
        super().__init__(team)
        self.vanished: dict[int, float] = {}
        self.alive: set[int] = set()
        self.holding: set[int] = set()  # robots whose liveliness token is there now
        # robots whose process ended without a result: when it first vanished (kept when its
        # token comes back, which a restart and a lapsed link both do)
        self.ended: dict[int, float] = {}
        self.restarted: dict[int, float] = {}  # a new process of a robot lost: first vanish
        self._subs.append(self.session.liveliness().declare_subscriber(
            self._key(team.name, "live", "*"), self._on_live, history=True))

    def _on_live(self, sample) -> None:
        import zenoh

        try:
            i = int(str(sample.key_expr).rsplit("/", 1)[-1])
        except ValueError:
            return
        with self.cv:
            if sample.kind == zenoh.SampleKind.DELETE:
                self.vanished.setdefault(i, time.monotonic())
                if i not in self.results:
                    self.ended.setdefault(i, self.vanished[i])
                self.holding.discard(i)
            else:  # (again:) a token back after a lapse of its link is a robot still running
                self.vanished.pop(i, None)
                self.alive.add(i)
                self.holding.add(i)
            self.cv.notify_all()

    def _on_status(self, sample) -> None:
        try:
            i = int(str(sample.key_expr).rsplit("/", 1)[-1])
            text = sample.payload.to_string()
        except (ValueError, AttributeError):
            return
        with self.cv:
            if text == "started" and i in self.ended and i not in self.results:
                self.restarted.setdefault(i, self.ended[i])  # module docstring
        super()._on_status(sample)

    def _on_result(self, sample) -> None:
        try:
            i = int(decode_packet(sample.payload.to_bytes())[0]["id"])
        except (WireError, KeyError, TypeError, ValueError):
            return
        with self.cv:
            restarted = i in self.restarted
            if restarted:
                self.heard[i] = time.monotonic()
        if restarted:  # the new process of a lost robot: stop its repeats, keep it lost
            self.ack(i)
            return
        super()._on_result(sample)


def _check_terms(team, results: dict) -> None:
    """InputError naming the first robot whose result was computed under other team-wide
    settings than the observer's team file holds (a TEAM.json edited in between): the run
    folder would describe a run that did not happen."""
    mine = team.shared_terms()
    for i in sorted(results):
        theirs = results[i][0].get("team_terms")
        if theirs is None or theirs == mine:
            continue
        keys = [x for x in sorted(set(theirs) | set(mine)) if theirs.get(x) != mine.get(x)]
        what = "; ".join(x if x == "comm_edges" else
                         f"{x} {theirs.get(x)!r} there, {mine.get(x)!r} here" for x in keys)
        raise InputError(f"robot {i} ({team.endpoint(i)}) ran with another team file than the "
                         f"observer's ({what}); give the observer the robots' TEAM.json")


def _written_off_unstarted(team, obs) -> set[int]:
    """Robots that never started (no liveliness token, no status) and that every neighbour
    wrote off in a published result: a robot written off is never taken back, so nothing of
    theirs can reach the run any more (one started now is told so and ends alone)."""
    out = set()
    for k in range(team.n):
        if k in obs.results or k in obs.alive or k in obs.status:
            continue
        nbrs = team.neighbours(k)
        if nbrs and all(j in obs.results and {str(x) for x in (
                obs.results[j][0].get("counters", {}).get("written_off") or {})} >= {str(k)}
                for j in nbrs):
            out.add(k)
    return out


def unreported(team, results: dict, lost) -> list[int]:
    """The robots of ``lost`` that ran to their end with their neighbours: every neighbour
    published a result and none wrote them off (``counters.written_off``), so each of their
    links was decided by both ends to the end, as in a whole run; only their own result never
    reached the observer (the observer's network path to them was cut)."""
    out = []
    for k in sorted(int(x) for x in lost):
        nbrs = team.neighbours(k)
        if k not in results and nbrs and all(
                j in results and str(k) not in {str(x) for x in (
                    results[j][0].get("counters", {}).get("written_off") or {})}
                for j in nbrs):
            out.append(k)
    return out


def _settle(obs, until: float) -> None:
    """With ``obs.cv`` held: wait until every robot whose result ``obs`` holds has stopped
    repeating it (module docstring), or ``until``; each repeat is acknowledged meanwhile."""
    while True:
        now = time.monotonic()
        if now >= until or all(i not in obs.holding and now - obs.heard.get(i, 0.0) >= QUIET_S
                               for i in obs.results):
            return
        obs.cv.wait(min(0.05, until - now))


def observe_team(team, *, timeout_s: float = 600.0, log=None) -> TeamRun:
    """Collect the results of ``team``'s robots started elsewhere; return a :class:`TeamRun`.

    Bound: returns or raises within ``timeout_s`` (plus at most one wait period of 0.05 s),
    and at most :data:`SETTLE_S` after it has every result; see the module docstring for when
    it stops.

    Raises
    ------
    TeamError
        A robot published ``failed: ...`` (named, with its message), or no robot published a
        result within ``timeout_s`` (names the first that never started, or never published).
    InputError
        The team file has no ``observer`` endpoint, or it cannot be listened on, or a robot
        published a result computed under other team-wide settings than the file's.
    """

    if not team.observer:
        raise InputError(f"team {team.name!r} has no observer endpoint; add "
                         "\"observer\": {\"endpoint\": \"tcp/HOST:PORT\"} to TEAM.json (the "
                         "robots connect to it) and start the robots again")
    log = log or (lambda s: None)
    obs = TeamObserver(team)
    run = TeamRun(team)
    t0 = time.monotonic()
    deadline = t0 + float(timeout_s)
    log(f"observer listening on {team.observer} for the {team.n} robots of {team.name!r}")
    try:
        with obs.cv:
            while True:
                now = time.monotonic()
                failed = sorted(i for i, s in obs.status.items()
                                if s.startswith("failed") and i not in obs.results)
                if failed:
                    i = failed[0]
                    raise TeamError(f"robot {i} ({team.endpoint(i)}) {obs.status[i]}")
                _check_terms(team, obs.results)
                lost = {i for i, t in obs.vanished.items()
                        if i not in obs.results and now - t > GRACE_S}
                lost |= set(obs.restarted)
                lost |= _written_off_unstarted(team, obs)
                if all(i in obs.results or i in lost for i in range(team.n)):
                    if not obs.results:  # nothing to write: a run folder of no link at all
                        raise TeamError(
                            "no robot's result reached this observer: every robot's process "
                            f"ended without one reaching it (robots "
                            f"{', '.join(map(str, sorted(lost)))}); "
                            "robots that ran to their end lost their results with their links "
                            "to the observer (paused or cut off longer than their lease), and "
                            "each robot's --result file holds what it decided: keep the "
                            "observer running and reachable, and run the team again")
                    for i in sorted(obs.restarted):
                        log(f"robot {i} ({team.endpoint(i)}) was started again after its "
                            "process had ended without a result: its neighbours wrote it off "
                            "and a robot written off is never taken back, so it is lost and "
                            "what its new process publishes is not used; start the whole team "
                            "again for its links")
                    off = sorted(_written_off_unstarted(team, obs))
                    if off:
                        log(f"robots {off} never started and every neighbour wrote them off: "
                            "lost")
                    break
                if now > deadline:
                    missing = [i for i in range(team.n) if i not in obs.results]
                    if not obs.results:
                        never = [i for i in missing if i not in obs.status
                                 and i not in obs.alive]
                        who = (never or missing)[0]
                        # the observer cannot tell a robot that never ran from one that
                        # gave up repeating its result before the observer listened
                        late = (", or it ended before this observer listened (a robot repeats "
                                "its result for start_timeout_s, at least 10 s): start the "
                                "observer before the robots end")
                        if who in never:
                            why = "never started" + late
                        elif who in obs.holding:
                            why = ("did not publish: it is still running; give the team longer, "
                                   f"a --timeout above {timeout_s:g} s")
                        else:
                            why = ("did not publish: its process ended without a result (its "
                                   "stderr says why)")
                        raise TeamError(
                            f"no robot published a result within {timeout_s:g} s; robot {who} "
                            f"({team.endpoint(who)}) {why}")
                    lost |= set(missing)
                    log(f"robots {missing} did not publish within {timeout_s:g} s: lost")
                    break
                obs.cv.wait(0.05)
            run.results = dict(obs.results)
            run.status = dict(obs.status)
            run.finished_at = dict(obs.finished_at)
            run.killed = {i: obs.restarted.get(i, obs.vanished.get(i, time.monotonic()))
                          for i in sorted(lost)}
            run.wall_s = run.published_s = time.monotonic() - t0
            _settle(obs, min(deadline, time.monotonic() + SETTLE_S))
        return run
    finally:
        obs.close()
