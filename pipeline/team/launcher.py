"""Start a team of robot processes on this machine and observe their results.

``--transport zenoh`` of ``run-formation``, ``run-formations`` and ``resolve`` comes here:
:func:`launch_team` finds free loopback ports, writes ``TEAM.json``, starts one process per
robot (by default forked from one *zygote* process that imported the robot program once,
:mod:`pipeline.team.zygote`; with ``fork=False`` each is ``python -m pipeline robot --team
TEAM.json --id I``, its own interpreter) and an *observer* in this process
that only subscribes to the robots' published results (it holds a Zenoh session listening on
its own endpoint; robots connect to it besides their neighbours, and it never relays between
robots: peers do not route for others). The caller builds the usual run folder from the
results.

No process is left behind: all robots (and the zygote) run in one process group that is
killed on any exit of the launcher (normal end, error, Ctrl-C, SIGTERM); on Linux each robot
also asks the kernel to kill it if its parent (the launcher, or the zygote) dies
(``PR_SET_PDEATHSIG``), and the zygote asks it of the launcher.
"""

from __future__ import annotations

import contextlib
import functools
import json
import os
import random
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pipeline.errors import TeamError, Terminated, die_with_parent
from pipeline.runfolder import make_scratch_folder
from pipeline.team.teamfile import (
    DEFAULT_OPTIONS,
    LAUNCHED_AT_ENV,
    RobotEntry,
    Team,
    round_timeout_options,
    write_team,
)
from pipeline.transport import NO_NEIGHBOUR_EXIT
from pipeline.transport.wire import WireError, decode_packet

__all__ = ["free_ports", "make_team", "launch_team", "TeamRun", "TeamError", "die_with_parent",
           "Observer", "TEAM_TIMEOUT_S", "team_time_limit", "team_round_timeout",
           "shared_zygote", "SharedZygote", "written_off", "lost_robots", "silent_grace_s"]


#: seconds a team may run before :func:`launch_team` kills it, unless the caller or
#: :func:`team_time_limit` (the commands' ``--team-timeout``) says otherwise
TEAM_TIMEOUT_S = 600.0

#: what the enclosing :func:`team_time_limit`, :func:`team_round_timeout` and
#: :func:`shared_zygote` set (their defaults outside them)
_within = {"time_limit": TEAM_TIMEOUT_S, "round_timeout": None, "zygote": None}


@contextlib.contextmanager
def _setting(name: str, seconds: float):
    """Within the block, ``_within[name]`` is ``seconds`` (restored on exit)."""
    old = _within[name]
    _within[name] = float(seconds)
    try:
        yield
    finally:
        _within[name] = old


def team_time_limit(seconds: float):
    """Within the block, every :func:`launch_team` not given its own ``timeout_s`` kills its
    team after ``seconds`` (``--team-timeout`` of the commands that take ``--transport``; a
    job that starts several teams, an online run one or more per step, gives each the
    limit)."""
    return _setting("time_limit", seconds)


def team_round_timeout(seconds: float):
    """Within the block, every team :func:`make_team` makes writes a silent neighbour off after
    ``seconds`` (``--round-timeout`` of the commands that take ``--transport``; a job that
    makes several teams, an online run some per step, gives it to each): its options take
    :func:`pipeline.team.teamfile.round_timeout_options` of ``seconds`` (``round_timeout_s``,
    and ``start_timeout_s`` and ``round_limit_s`` at least twice it) where the caller's
    options do not set them. A team read from a file (``robot``, ``observe``) keeps its
    file's."""
    return _setting("round_timeout", seconds)


#: where :func:`free_ports` draws when the kernel's ephemeral range cannot be read
_EPHEMERAL_DEFAULT = (32768, 60999)


def ephemeral_range() -> tuple[int, int]:
    """The kernel's ephemeral port range (``net.ipv4.ip_local_port_range``): the ports it hands
    out for ``bind(port 0)`` and as the local end of every outgoing connection."""
    try:
        lo, hi = (int(x) for x in Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split())
    except (OSError, ValueError):
        return _EPHEMERAL_DEFAULT
    return lo, hi


def free_ports(k: int, host: str = "127.0.0.1") -> list[int]:
    """``k`` distinct TCP ports that were free on ``host`` a moment ago, drawn at random below
    the kernel's ephemeral range.

    A robot binds its port only once its process runs. A port the kernel hands out itself
    (``bind(port 0)``) lies in the ephemeral range, which every outgoing connection on the
    machine draws its local port from too, so a robot's or another program's connection
    could take it in between ("the port is in use"); below the range the kernel assigns no
    port on its own. Each drawn port is checked free by binding it; the draw falls back to
    the kernel's choice if fewer than ``k`` are found."""
    lo, _ = ephemeral_range()
    first = 10000 if lo > 12000 else 1024
    rng = random.SystemRandom()
    socks, ports = [], []
    try:
        if lo - first >= 4 * k:
            for port in rng.sample(range(first, lo), min(lo - first, 8 * k + 64)):
                if len(ports) == k:
                    break
                s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
                try:
                    s.bind((host, port))
                except OSError:
                    s.close()
                    continue
                socks.append(s)
                ports.append(port)
        while len(ports) < k:
            s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            s.bind((host, 0))
            socks.append(s)
            ports.append(s.getsockname()[1])
    finally:
        for s in socks:
            s.close()
    return ports


def make_team(name: str, comm_edges, data: dict, options: dict | None = None,
              host: str = "127.0.0.1", n: int | None = None) -> Team:
    """A loopback team with free ports for every robot and the observer.

    ``comm_edges`` is an edge array: an edge listed twice is an InputError naming it
    (:func:`pipeline.commgraph.check_comm_edges`, through the team file's own check).
    ``options`` over :data:`~pipeline.team.teamfile.DEFAULT_OPTIONS`; within
    :func:`team_round_timeout` its timeouts where ``options`` sets none; ``closed_at_start``
    unless ``options`` says otherwise (the launcher never starts a robot again in a team).
    """
    e = np.asarray(comm_edges, dtype=np.int64).reshape(-1, 2)
    n = int(n if n is not None else e.max() + 1)
    ports = free_ports(n + 1, host)
    robots = [RobotEntry(i, f"tcp/{host}:{p}") for i, p in enumerate(ports[:n])]
    silence = _within["round_timeout"]
    timeouts = {} if silence is None else round_timeout_options(silence)
    # its robots are never started again under their ids: one that ends while starting is
    # written off by its neighbours at once (closed_at_start)
    opts = {**DEFAULT_OPTIONS, **timeouts, "closed_at_start": True, **(options or {})}
    team = Team(name, robots, e, data, opts, observer=f"tcp/{host}:{ports[n]}")
    from pipeline.team.teamfile import parse_team

    return parse_team(team.to_json())  # the same checks as a hand-written file


def _dies_with(parent_pid: int):
    """A ``preexec_fn`` for a child of ``parent_pid``: :func:`die_with_parent`."""
    return functools.partial(die_with_parent, parent_pid)


class _ForkedRobot:
    """A robot forked by the zygote, seen like a :class:`subprocess.Popen` (pid, poll, wait,
    kill); its exit code comes from the zygote's ``exit`` line. ``gone`` is set once the
    zygote's lines ended (it died, and its robots with it): no exit line comes any more, and
    :meth:`wait` returns at once (``None`` for a robot whose exit was not reported)."""

    def __init__(self, i: int, pid: int, codes: dict, cv: threading.Condition,
                 gone: threading.Event) -> None:
        self.i, self.pid, self._codes, self._cv, self._gone = int(i), int(pid), codes, cv, gone

    @property
    def returncode(self):
        return self._codes.get(self.i)

    def poll(self):
        return self._codes.get(self.i)

    def wait(self, timeout: float | None = None):
        end = None if timeout is None else time.monotonic() + timeout
        with self._cv:
            while self.i not in self._codes and not self._gone.is_set():
                left = None if end is None else end - time.monotonic()
                if left is not None and left <= 0:
                    raise subprocess.TimeoutExpired(f"robot {self.i}", timeout)
                self._cv.wait(0.05 if left is None else min(left, 0.05))
        return self._codes.get(self.i)

    def kill(self) -> None:
        if self.i in self._codes:  # reaped: its pid may belong to another process by now
            return
        with contextlib.suppress(ProcessLookupError):
            os.kill(self.pid, signal.SIGKILL)


def _read_zygote(stream, procs: dict, codes: dict, cv: threading.Condition,
                 gone: threading.Event) -> None:
    """Reader thread: the zygote's ``pid I PID`` and ``exit I CODE`` lines; ``gone`` is set
    when they end."""
    try:
        for raw in stream:
            parts = raw.decode(errors="replace").split()
            if len(parts) != 3 or parts[0] not in ("pid", "exit"):
                continue
            _note_robot(parts[0], int(parts[1]), int(parts[2]), procs, codes, cv, gone)
    except (OSError, ValueError):  # the stream closed under the reader
        pass
    finally:
        _zygote_gone(cv, gone)


def _zygote_gone(cv: threading.Condition, gone: threading.Event) -> None:
    """The zygote's lines ended: no robot's exit will be reported any more."""
    with cv:
        gone.set()
        cv.notify_all()


def _note_robot(kind: str, i: int, v: int, procs: dict, codes: dict,
                cv: threading.Condition, gone: threading.Event) -> None:
    """Record a zygote's ``pid`` (``v`` the pid) or ``exit`` (``v`` the code) line of robot
    ``i``."""
    with cv:
        if kind == "pid":
            procs[i] = _ForkedRobot(i, v, codes, cv, gone)
        else:
            codes[i] = v
        cv.notify_all()


class SharedZygote:
    """One serving zygote (``python -m pipeline.team.zygote --serve``) for every team
    :func:`launch_team` starts within :func:`shared_zygote`: the robot program is imported
    once for the job instead of once per team (an online run over Zenoh starts three teams
    per step). Started at the first team; a team's robots are told apart by a tag on the
    zygote's lines. A team that ends kills its own robots (by pid: the zygote lives on) and
    waits for their exits; robots of an ended team that the zygote reports only afterwards
    are killed on sight."""

    def __init__(self) -> None:
        self.proc: subprocess.Popen | None = None
        self.teams: dict = {}       # tag -> (procs, codes, cv, gone, the zygote's Popen)
        self.ended: set = set()     # tags of teams that ended
        self.dead: set = set()      # the zygote Popens whose lines ended
        self.lock = threading.Lock()
        self.count = 0
        # the zygote's standard error: a file without a name (nothing is left behind when
        # the launcher is killed), each zygote its own
        self._log = None

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def _start(self, env: dict) -> None:
        self.close()
        self._log = tempfile.TemporaryFile(prefix="fm-zygote-")  # noqa: SIM115 - closed in close
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "pipeline.team.zygote", "--serve"],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self._log, env=env,
            process_group=0, preexec_fn=_dies_with(os.getpid()))
        threading.Thread(target=self._read, args=(self.proc, self.proc.stdout),
                         daemon=True).start()

    def _read(self, proc, stream) -> None:
        try:
            for raw in stream:
                parts = raw.decode(errors="replace").split()
                if len(parts) != 4 or parts[0] not in ("pid", "exit"):
                    continue
                tag, i, v = parts[1], int(parts[2]), int(parts[3])
                # under the lock: a team ending now (end_team) either finds the robot noted
                # among its own, which it kills, or has ended before, and it is killed here
                with self.lock:
                    team = self.teams.get(tag)
                    if tag in self.ended and parts[0] == "pid":
                        with contextlib.suppress(ProcessLookupError):
                            os.kill(v, signal.SIGKILL)
                    if team is not None:
                        _note_robot(parts[0], i, v, *team[:4])
        except (OSError, ValueError):  # the stream closed under the reader
            pass
        finally:
            # this zygote died (its robots with it): its teams hear of no more exits
            with self.lock:
                self.dead.add(proc)
                served = [t for t in self.teams.values() if t[4] is proc]
            for _, _, cv, gone, _ in served:
                _zygote_gone(cv, gone)

    def start_team(self, team_path: Path, workdir: Path, procs: dict, codes: dict,
                   cv: threading.Condition, env: dict, gone: threading.Event) -> str:
        """Ask the zygote (started now if it is not running) to fork the robots of the team
        in ``team_path``; their ``pid``/``exit`` lines go to ``procs``/``codes`` under
        ``cv``, and ``gone`` is set if the zygote dies. Returns the team's tag."""
        if not self.alive():
            self._start(env)
        with self.lock:
            self.count += 1
            tag = str(self.count)
            self.teams[tag] = (procs, codes, cv, gone, self.proc)
            dead = self.proc in self.dead
        if dead:  # its lines ended before the team was noted
            _zygote_gone(cv, gone)
        line = json.dumps({"tag": tag, "team": str(team_path), "workdir": str(workdir),
                           "launched_at": repr(time.time())})
        try:
            self.proc.stdin.write(line.encode() + b"\n")
            self.proc.stdin.flush()
        except (BrokenPipeError, OSError):
            pass  # the zygote died: the launcher sees it end and names its log
        return tag

    def end_team(self, tag: str) -> None:
        """The team ``tag`` ended: a robot of it forked from now on is killed at once (its
        exits are still recorded, until :meth:`forget`)."""
        with self.lock:
            self.ended.add(tag)

    def forget(self, tag: str) -> None:
        """The team ``tag``'s robots are gone: no line of it is recorded any more."""
        with self.lock:
            self.teams.pop(tag, None)

    def close(self) -> None:
        """Stop the zygote and whatever robots it still has (the next team starts another)."""
        if self.proc is not None:
            with contextlib.suppress(Exception):
                self.proc.stdin.close()
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(self.proc.pid, signal.SIGKILL)
            with contextlib.suppress(Exception):
                self.proc.wait(timeout=5)
            if self.proc.stdout is not None:
                with contextlib.suppress(Exception):
                    self.proc.stdout.close()
            self.proc = None
        if self._log is not None:
            self._log.close()
            self._log = None

    def log_tail(self) -> str:
        """The last error line of the running (or last) zygote's standard error."""
        if self._log is None:
            return ""
        fd = self._log.fileno()
        size = os.fstat(fd).st_size
        return _last_lines(os.pread(fd, min(size, 1 << 16), max(0, size - (1 << 16)))
                           .decode(errors="replace"))


@contextlib.contextmanager
def shared_zygote():
    """Within the block, every :func:`launch_team` that forks its robots (the default) forks
    them from one :class:`SharedZygote`, stopped when the block ends (a block within another
    uses the outer one)."""
    if _within["zygote"] is not None:
        yield _within["zygote"]
        return
    zygote = SharedZygote()
    _within["zygote"] = zygote
    try:
        yield zygote
    finally:
        _within["zygote"] = None
        zygote.close()


@dataclass
class TeamRun:
    """What the observer collected and how the processes ended."""

    team: Team
    results: dict = field(default_factory=dict)     # id -> (header, arrays)
    status: dict = field(default_factory=dict)      # id -> last status line
    exit_codes: dict = field(default_factory=dict)  # id -> return code
    killed: dict = field(default_factory=dict)      # id -> monotonic time of the kill
    #: id -> monotonic time of a ``kill -STOP`` (fault injection: ``kill`` with ``stop_s``)
    frozen: dict = field(default_factory=dict)
    finished_at: dict = field(default_factory=dict)  # id -> monotonic time of the result
    wall_s: float = 0.0
    start_s: float = 0.0
    published_s: float = 0.0  # from the launch to the last result received
    stderr: dict = field(default_factory=dict)      # id -> last lines of the robot's stderr
    #: with ``stop_at_loss``: the robots whose processes had ended without publishing when
    #: the team was stopped (in increasing order; the others killed, their results not waited
    #: for); else empty
    stopped_by: list = field(default_factory=list)
    #: id -> monotonic time the launcher killed it as silent: its process ran on without
    #: publishing or computing for :func:`silent_grace_s` after every other robot had
    #: published or ended (frozen for good, hung); it is lost (:func:`lost_robots`)
    silenced: dict = field(default_factory=dict)

    @property
    def survivors(self) -> list[int]:
        return sorted(self.results)


class Observer:
    """Subscribes to results and statuses; acknowledges every result."""

    def __init__(self, team: Team) -> None:
        from pipeline.transport.zenoh_transport import key, open_session

        self.team = team
        self.results: dict = {}
        self.status: dict = {}
        self.seen: dict = {}
        self.finished_at: dict = {}
        self.heard: dict = {}  # robot -> when its result (first or a repeat) last came
        self.cv = threading.Condition()
        # the robots' lease (link_timeouts of their round timeout): with Zenoh's default of
        # 10 s a pause of the observer's process longer than that closed its links
        longest = max(float(team.options_for(i)["round_timeout_s"]) for i in range(team.n))
        self.session = open_session([team.observer], [], "observer", round_timeout_s=longest)
        self._key = key
        self._ended: list = []  # the ``ended`` tokens declared (kept alive with the session)
        self._subs = [
            self.session.declare_subscriber(key(team.name, "result", "*"), self._on_result),
            self.session.declare_subscriber(key(team.name, "status", "*"), self._on_status)]

    def _on_result(self, sample) -> None:
        try:
            header, msgs = decode_packet(sample.payload.to_bytes())
        except WireError:
            return
        i = int(header["id"])
        self.ack(i)  # every repeat: an earlier receipt may have been lost with its link
        with self.cv:
            self.heard[i] = time.monotonic()
            if i not in self.results:
                self.results[i] = (header, msgs[0][1] if msgs else {})
                self.finished_at[i] = self.heard[i]
            self.cv.notify_all()

    def ack(self, i: int) -> None:
        """Acknowledge robot ``i``'s result. A result still arriving while the observer
        closes (it stopped on another robot's error): no receipt then, and no traceback from
        Zenoh's callback thread."""
        with contextlib.suppress(Exception):
            self.session.put(self._key(self.team.name, "ack", i), b"ok")

    def _on_status(self, sample) -> None:
        i = int(str(sample.key_expr).rsplit("/", 1)[-1])
        with self.cv:
            self.status[i] = sample.payload.to_string()
            self.seen.setdefault(i, []).append(self.status[i])
            self.cv.notify_all()

    def ended(self, i: int) -> None:
        """Tell robot ``i``'s neighbours that its process ended (it did not publish): a
        liveliness token ``fm/<team>/ended/<i>`` for the rest of the team, which its
        neighbours find by a liveliness query while it is unheard (:meth:`pipeline.transport.
        zenoh_transport.ZenohTransport._ask_ended`). A robot killed while starting, before its
        neighbours heard it, would otherwise be waited for until their start timeout."""
        with contextlib.suppress(Exception):
            self._ended.append(self.session.liveliness().declare_token(
                self._key(self.team.name, "ended", int(i))))

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.session.close()


def silent_grace_s(team: Team) -> float:
    """How long :func:`launch_team` waits for the robots that neither published nor ended once
    every other robot of ``team`` has: three times the longest ``round_timeout_s`` of its
    robots, counted from the last result, end or status line any robot of the team gave, or
    CPU time one of those robots' processes used (a robot still computing is not silent;
    where the system does not tell a process's CPU time, from the others' last sign only).

    The round timeout is the silence after which the robots themselves write a neighbour off.
    A robot still running when all the others are done was written off by its neighbours
    (frozen for good, a host suspended or cut off, or hung), or has only its own last work
    left (its neighbours' exchanges with it are over), or waits out the silence of a
    neighbour that is silent too: one round timeout covers that wait, the rest its last
    work. A frozen robot's neighbours end about one round timeout after it froze, and once
    resumed it writes them off and publishes within a few seconds: frozen for up to about
    three round timeouts in all, it still publishes in time."""
    return 3.0 * max(float(team.options_for(i)["round_timeout_s"]) for i in range(team.n))


def _cpu_ticks(pid: int) -> int | None:
    """CPU time process ``pid`` used so far (user and system, in clock ticks, Linux's
    ``/proc/PID/stat``), or None where it cannot be read."""
    try:
        fields = Path(f"/proc/{int(pid)}/stat").read_text().rsplit(")", 1)[1].split()
        return int(fields[11]) + int(fields[12])
    except (OSError, ValueError, IndexError):
        return None


def launch_team(team: Team, workdir: str | Path | None = None, *, timeout_s: float | None = None,
                kill: tuple | None = None, log=None,
                fork: bool = True, stop_at_loss: bool = False, start=None) -> TeamRun:
    """Run every robot of ``team`` as a process on this machine; return what they published.

    Parameters
    ----------
    team : Team — loopback endpoints (see :func:`make_team`), with an observer endpoint
    workdir : folder for ``TEAM.json`` and the robots' logs (default: a temporary folder)
    timeout_s : float or None — overall limit; the team is killed after it (None: the
        limit of the enclosing :func:`team_time_limit`, else :data:`TEAM_TIMEOUT_S`)
    kill : ``(robot, status, delay_s)`` or None — fault injection: ``kill -9`` of ``robot``
        ``delay_s`` seconds after it published ``status`` (``started``, ``consistency``,
        ``fusion``); ``(robot, status, delay_s, stop_s)``: ``kill -STOP`` instead, and
        ``kill -CONT`` ``stop_s`` seconds later (a host suspended, or cut off for a while: its
        process does not end, its neighbours write it off after their round timeout; the
        robot is in :attr:`TeamRun.frozen`, not in :attr:`TeamRun.killed`). A robot that
        neither publishes, ends nor computes for :func:`silent_grace_s` after every other
        robot has published or ended (frozen for good, or hung) is killed then and counted lost
        (:attr:`TeamRun.silenced`; with ``stop_at_loss`` its end stops the team as any
        other), instead of holding the team until ``timeout_s``
    log : callable(str) or None
    fork : bool — fork the robots from one zygote that imported the robot program once
        (:mod:`pipeline.team.zygote`; default), or start each as its own interpreter
    stop_at_loss : bool — stop the team as soon as a robot's process ends without publishing
        (killed, ended otherwise without an error, or with exit code 3: it heard no
        neighbour, :data:`~pipeline.transport.NO_NEIGHBOUR_EXIT`), killing the others
        (:attr:`TeamRun.stopped_by`), for a caller that will start the team again anyway
        (an online step, :mod:`pipeline.runs.online`): the survivors would otherwise finish
        without it, and a robot lost before the start handshake is written off only after
        ``start_timeout_s``. Default: the survivors finish, as a team without a launcher
        would
    start : callable or None — ``start(i, argv, **popen)`` starts robot ``i``'s program
        ``argv`` (``python -m pipeline robot ...``) with :class:`subprocess.Popen`'s keywords
        ``popen`` and returns its process, e.g. on a host of its own
        (:meth:`pipeline.team.netns.NetnsRig.start`); each robot is then its own interpreter
        (``fork`` is not used). None: ``subprocess.Popen(argv, **popen)``

    Raises
    ------
    TeamError
        A robot exited with an error before publishing its result (named, with its last
        stderr line), or the team did not finish within ``timeout_s``. A robot that heard no
        neighbour (exit code 3) is no error but lost, as a killed one, with ``stop_at_loss``
        or when every neighbour of it was lost too (killed, frozen, ended without
        publishing); otherwise its neighbours ran and it could not reach them (a wrong
        address, the network), an error.
    """
    log = log or (lambda s: print(s, file=sys.stderr, flush=True))
    timeout_s = _within["time_limit"] if timeout_s is None else float(timeout_s)
    tmp = observer = None
    procs: dict[int, subprocess.Popen] = {}
    errfiles = {}
    pgid = None
    old_handlers = {}

    def kill_all(*_):
        if pgid is not None:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(pgid, signal.SIGKILL)
        for p in procs.values():
            with contextlib.suppress(ProcessLookupError):
                p.kill()

    # a signal while the team is being stopped (a second Ctrl-C, or the one `timeout`
    # forwards) must not break the cleanup: the observer's Zenoh session left open keeps the
    # interpreter alive. It is held until the cleanup is done, then raised. The first one is
    # also kept ("got"): Python drops the exception of a handler that runs within its hooks
    # around a fork (starting the zygote or a robot), and the team then ran on to its end
    # after a Ctrl-C; the wait below raises it again.
    stopping = {"now": False, "pending": None, "got": None}

    def interrupt(signum):
        return KeyboardInterrupt() if signum == signal.SIGINT else Terminated()

    def on_signal(signum, frame):
        kill_all()
        if stopping["now"]:
            stopping["pending"] = signum
            return
        stopping["now"], stopping["got"] = True, signum
        raise interrupt(signum)

    def interrupted() -> None:
        """Raise the signal a handler took, if Python dropped its exception."""
        if stopping["got"] is not None:
            raise interrupt(stopping["got"])

    # the handlers first: a signal from here on stops the team and removes its folder
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            old_handlers[sig] = signal.signal(sig, on_signal)
    zygote = None
    gone = threading.Event()  # the zygote's lines ended
    over = threading.Event()  # the team ended: a robot frozen by ``kill`` is not woken
    pending = kill is not None  # the fault injection is still to come
    fork = fork and start is None
    shared, tag = (_within["zygote"] if fork else None), None
    try:
        if workdir is None:
            tmp = make_scratch_folder("fm-team-")
            workdir = tmp
        workdir = Path(workdir)
        workdir.mkdir(parents=True, exist_ok=True)
        team_path = write_team(workdir / "TEAM.json", team)
        run = TeamRun(team)
        observer = Observer(team)
        t0 = time.monotonic()
        env = {**os.environ, "PYTHONUNBUFFERED": "1", "OMP_NUM_THREADS": "1",
               "OPENBLAS_NUM_THREADS": "1"}
        if shared is not None:
            tag = shared.start_team(team_path, workdir, procs, run.exit_codes, observer.cv, env,
                                    gone)
            zygote = shared.proc
        elif fork:
            env[LAUNCHED_AT_ENV] = repr(time.time())
            errfiles["zygote"] = open(workdir / "zygote.log", "wb")  # noqa: SIM115
            zygote = subprocess.Popen(
                [sys.executable, "-m", "pipeline.team.zygote", str(team_path), str(workdir)],
                stdout=subprocess.PIPE, stderr=errfiles["zygote"], env=env, process_group=0,
                preexec_fn=_dies_with(os.getpid()))
            pgid = zygote.pid
            threading.Thread(target=_read_zygote, daemon=True,
                             args=(zygote.stdout, procs, run.exit_codes, observer.cv,
                                   gone)).start()
        else:
            for i in range(team.n):
                env[LAUNCHED_AT_ENV] = repr(time.time())
                errfiles[i] = open(workdir / f"robot{i}.log", "wb")  # noqa: SIM115
                argv = [sys.executable, "-m", "pipeline", "robot", "--team", str(team_path),
                        "--id", str(i)]
                popen = dict(stdout=errfiles[i], stderr=subprocess.STDOUT, env=env,
                             process_group=0 if pgid is None else pgid,
                             preexec_fn=_dies_with(os.getpid()))
                procs[i] = subprocess.Popen(argv, **popen) if start is None \
                    else start(i, argv, **popen)
                if pgid is None:
                    pgid = procs[i].pid
        run.start_s = time.monotonic() - t0
        deadline = t0 + timeout_s
        grace_s = silent_grace_s(team)
        # what the robots last did (results, ends, status lines; once every other robot is
        # done, the CPU time of those still running) and since when: a robot silent for the
        # grace after every other one published or ended is killed
        progress, quiet_since = None, time.monotonic()
        announced: set = set()  # robots whose end without a result the observer announced

        def neighbours_lost(i: int) -> bool:
            """Whether every neighbour of robot ``i`` was lost: its process ended without
            publishing, or the fault injection or the launcher stopped it."""
            return all(k in run.killed or k in run.frozen or k in run.silenced
                       or (k in run.exit_codes and k not in observer.results)
                       for k in team.neighbours(i))

        with observer.cv:
            while True:
                interrupted()
                for i, p in list(procs.items()):
                    if i not in run.exit_codes and p.poll() is not None:
                        run.exit_codes[i] = p.returncode
                for i in sorted(set(run.exit_codes) - set(observer.results) - announced):
                    observer.ended(i)  # its neighbours may not know yet
                    announced.add(i)
                running = [i for i in range(team.n)
                           if i not in observer.results and i not in run.exit_codes]
                if gone.is_set() and running:
                    # the zygote died: its robots die with it (PR_SET_PDEATHSIG) and no exit
                    # of theirs comes
                    code = None
                    with contextlib.suppress(Exception):
                        code = zygote.wait(timeout=1)
                    when = ("before starting every robot" if len(procs) < team.n else
                            f"while robot {running[0]} ({team.endpoint(running[0])}) ran, "
                            "which ended with it")
                    why = (_tail(workdir / "zygote.log") if shared is None else
                           shared.log_tail())
                    raise TeamError("the robots' zygote (python -m pipeline.team.zygote) ended"
                                    + ("" if code is None else f" with exit code {code}")
                                    + f" {when}; nothing was kept: run again"
                                    + (f" ({why})" if why else ""))
                if pending and kill[0] in procs:
                    k, status, delay = kill[:3]
                    if status in observer.seen.get(k, ()):
                        pending = False
                        observer.cv.release()
                        try:
                            time.sleep(delay)
                            # a robot that ended meanwhile is not there to kill (its pid may
                            # be another process's by now)
                            alive = procs[k].poll() is None
                            if alive and len(kill) > 3:
                                _freeze(procs[k], float(kill[3]), over)
                            elif alive:
                                procs[k].kill()
                        finally:
                            observer.cv.acquire()
                        if not alive:
                            log(f"robot {k} ended before its kill -9")
                        elif len(kill) > 3:
                            run.frozen[k] = time.monotonic()
                            log(f"kill -STOP robot {k} (pid {procs[k].pid}) for {kill[3]:g} s")
                        else:
                            run.killed[k] = time.monotonic()
                            log(f"kill -9 robot {k} (pid {procs[k].pid})")
                failed = [i for i, c in run.exit_codes.items()
                          if c not in (0, -signal.SIGKILL) and i not in observer.results
                          and not (c == NO_NEIGHBOUR_EXIT
                                   and (stop_at_loss or neighbours_lost(i)))]
                if failed:
                    i = failed[0]
                    last = _tail(workdir / f"robot{i}.log")
                    raise TeamError(f"robot {i} ({team.endpoint(i)}) failed with exit code "
                                    f"{run.exit_codes[i]}: {last}")
                gone_early = sorted(int(i) for i in run.exit_codes if i not in observer.results)
                if stop_at_loss and gone_early:
                    # every robot gone by now: two may end within one poll
                    run.stopped_by = gone_early
                    log(f"robot{'s' if len(gone_early) > 1 else ''} "
                        f"{', '.join(map(str, gone_early))} ended without publishing: the "
                        "team is stopped (it will be started again)")
                    break
                ended = set(observer.results) | set(run.exit_codes)
                if len(ended) == team.n and all(i in observer.results or i in run.exit_codes
                                                for i in range(team.n)):
                    # every robot published or is gone
                    if all(p.poll() is not None or i in observer.results
                           for i, p in procs.items()):
                        break
                now = time.monotonic()
                silent = [i for i in range(team.n) if i not in observer.results
                          and i not in run.exit_codes and i not in run.silenced]
                waiting = bool(silent) and len(silent) < team.n and len(procs) == team.n
                seen = (len(set(observer.results) | set(run.exit_codes)),
                        sum(len(v) for v in observer.seen.values()),
                        *(_cpu_ticks(procs[i].pid) for i in (silent if waiting else ())))
                if seen != progress:
                    progress, quiet_since = seen, now
                if waiting and now - quiet_since > grace_s:
                    for i in silent:
                        procs[i].kill()
                        run.silenced[i] = time.monotonic()
                        log(f"robot {i} ({team.endpoint(i)}) neither published nor ended "
                            f"{grace_s:g} s after the others (three round timeouts): "
                            "killed, counted lost")
                if time.monotonic() > deadline:
                    missing = sorted(set(range(team.n)) - set(observer.results))
                    never = [i for i in missing if i not in observer.status]
                    who = never or missing
                    raise TeamError(f"the team of {team.n} robot processes did not end "
                                    f"within {timeout_s:g} s (robot {who[0]} "
                                    f"({team.endpoint(who[0])}) "
                                    f"{'never started' if never else 'did not publish a result'}"
                                    "); a large team on a slow machine needs longer: raise "
                                    "--team-timeout")
                observer.cv.wait(0.05)
        run.published_s = time.monotonic() - t0
        # wait for the processes that published to exit (a team stopped at a loss: those
        # that did not publish are killed below, not waited for)
        for i, p in procs.items():
            if not run.stopped_by or i in observer.results:
                with contextlib.suppress(subprocess.TimeoutExpired):
                    p.wait(timeout=5)
            run.exit_codes[i] = p.poll()
        run.wall_s = time.monotonic() - t0
        run.results = dict(observer.results)
        run.status = dict(observer.status)
        run.finished_at = dict(observer.finished_at)
        run.stderr = {i: _tail(workdir / f"robot{i}.log", 20) for i in procs}
        interrupted()
        return run
    finally:
        stopping["now"] = True
        if shared is not None and tag is not None:
            shared.end_team(tag)
        over.set()
        kill_all()
        if shared is not None:
            # the zygote serves the next team: this team's robots only, reaped by it
            for p in list(procs.values()):
                with contextlib.suppress(Exception):
                    p.wait(timeout=5)
            if tag is not None:
                shared.forget(tag)
        elif zygote is not None:
            # the zygote reaps its robots; killed with them, it reports no more exits, and
            # robots it did not reap are reaped by init
            with contextlib.suppress(Exception):
                zygote.wait(timeout=5)
            if zygote.stdout is not None:
                zygote.stdout.close()
        else:
            for p in procs.values():
                with contextlib.suppress(Exception):
                    p.wait(timeout=5)
        for f in errfiles.values():
            f.close()
        if observer is not None:
            observer.close()
        if tmp is not None:  # before the handlers go: a signal now still waits for it
            shutil.rmtree(tmp, ignore_errors=True)
        for sig, h in old_handlers.items():
            signal.signal(sig, h)
        if stopping["pending"] is not None:
            raise interrupt(stopping["pending"])


def written_off(run: TeamRun, named: dict) -> list[int]:
    """Of the robots ``named`` lost by others (robot -> the robots that wrote it off), those
    the team lost: a robot that published is not lost when every robot that named it
    published after it and was itself named lost. A robot frozen for a while (a host
    suspended) writes off, once it runs again, the neighbours that had ended without it;
    they are not lost, it is (its neighbours named it before it published)."""
    named = {int(k): [int(j) for j in v] for k, v in named.items()}
    done = run.finished_at

    def innocent(k: int) -> bool:
        return k in done and all(j in named and j in done and done[j] > done[k]
                                 for j in named[k])

    return sorted(k for k in named if not innocent(k))


def lost_robots(run: TeamRun, named: dict | None = None) -> list[int]:
    """The robots ``run`` lost: those it was stopped by (``stop_at_loss``), else those that
    did not publish (those the launcher killed as silent among them); those killed by the
    fault injection; and of those ``named`` lost by others (robot -> the robots that named
    it), the ones :func:`written_off` holds lost."""
    gone = set(run.stopped_by) if run.stopped_by \
        else set(range(run.team.n)) - set(run.results)
    return sorted(gone | {int(k) for k in run.killed} | set(written_off(run, named or {})))


def _freeze(proc, stop_s: float, over: threading.Event) -> None:
    """``kill -STOP`` of a robot process, and ``kill -CONT`` ``stop_s`` seconds later unless
    its team ended first (its robots are killed then, and its pid may be another's)."""
    os.kill(proc.pid, signal.SIGSTOP)

    def wake() -> None:
        if not over.wait(stop_s) and proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.kill(proc.pid, signal.SIGCONT)

    threading.Thread(target=wake, daemon=True).start()


def _tail(path: Path, lines: int = 1) -> str:
    try:
        return _last_lines(path.read_text(errors="replace"), lines)
    except OSError:
        return ""


def _last_lines(text: str, lines: int = 1) -> str:
    """The last ``lines`` lines of ``text``; with one, its last error line (or last line)."""
    text = text.strip().splitlines()
    if lines == 1:
        errs = [t for t in text if t.startswith("error:") or "Error" in t]
        return (errs or text or [""])[-1]
    return "\n".join(text[-lines:])


def team_summary(run: TeamRun) -> dict:
    """Per-robot figures of a team run (for the report's ``team`` section)."""
    rob = {}
    for i in range(run.team.n):
        if i in run.results:
            h = run.results[i][0]
            c = h["counters"]
            rob[str(i)] = {"rounds": c["round"], "messages": c["messages"], "bytes": c["bytes"],
                           "wire_bytes": c["wire_bytes"], "wire_packets": c["wire_packets"],
                           "bytes_by_kind": c.get("bytes_by_kind", {}),
                           "wire_bytes_by_stage": h.get("wire_bytes_by_stage", {}),
                           "dropped": c["dropped"], "silent": c["silent"],
                           "peak_rss_bytes": h["peak_rss_bytes"],
                           "peak_memory_bytes": h["peak_memory_bytes"],
                           "timings_s": h["timings_s"], "handshake_s": h.get("handshake_s"),
                           "since_launch_s": h.get("since_launch_s")}
        else:
            # lost: "killed" (its process ended or went silent), "started" whether it ever
            # said so (a robot never started is lost too), "silenced" whether the launcher
            # killed it, silent after the others had ended (silent_grace_s)
            rob[str(i)] = {"result": None, "exit_code": run.exit_codes.get(i),
                           "killed": i in run.killed, "started": i in run.status,
                           "silenced": i in run.silenced}
    # comm edges a robot that published never matched: it wrote the neighbour off before
    # their features crossed, so the pair's links are missing (not cut); a links team
    # reads its links and matches nothing
    unmatched = []
    if run.team.data.get("kind") in ("formation", "images"):
        for a, b in sorted(sorted(map(int, e)) for e in np.asarray(run.team.comm_edges).tolist()):
            pairs = [{(int(m["i"]), int(m["j"])) for m in run.results[x][0].get("matches", [])}
                     for x in (a, b) if x in run.results]
            if any((a, b) not in p and (b, a) not in p for p in pairs):
                unmatched.append([a, b])
    return {"transport": "zenoh", "robots": rob, "wall_s": round(run.wall_s, 4),
            **({"unmatched_pairs": unmatched} if unmatched else {}),
            "process_start_s": round(run.start_s, 4),
            "last_result_s": round(run.published_s, 4),
            "killed": {str(k): True for k in run.killed},
            "team": json.loads(json.dumps(run.team.to_json()))}
