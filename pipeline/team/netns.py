"""Hosts on one Linux machine: one network namespace per robot, one cable per comm edge.

A team tested as if its robots were separate machines: each robot runs in its own network
namespace (``ip netns add``) with its own address, and every edge ``(i, j)`` of the comm graph
is its own point-to-point cable, a veth pair with one end in each robot's namespace. So the
robots talk over real sockets between addresses, and the network's faults are made where a
real network makes them:

* **partition / heal** of one link: its cable goes down, then up (``ip link set DEV down|up``
  at both ends): only the robots of that edge stop hearing each other;
* **bandwidth cap** per link: a token bucket on both ends of its cable
  (``tc qdisc add dev DEV root tbf rate R burst 32kbit latency 400ms``), e.g. ``1mbit``,
  ``256kbit``;
* **a host frozen and resumed** (``SIGSTOP`` / ``SIGCONT`` of its program) and **a host
  killed** (``SIGKILL``): :meth:`NetnsRig.signal`.

Faults this machine cannot make: packet loss, delay and reordering need the ``netem``
queueing discipline, which this kernel does not have (``tc qdisc add ... netem`` fails with
"Specified qdisc kind is unknown"); message loss is injected by the robots instead
(``drop_prob``).

Addressing: robot ``i`` owns ``10.78.H.L`` (``H, L`` from ``i + 1``) on its loopback, which is
where it listens (:meth:`endpoint`). A cable ``(i, j)`` has no address of its own; each end has a
``/32`` route to the other robot's address through it (source: the robot's own address), so a
packet between neighbours crosses exactly their cable and the cable's interface counters
(``ip -s link``) count what crossed the socket, headers included (:meth:`link_bytes`). Robots
that are not neighbours have no route to each other, as the comm graph says.

Needs root, ``ip`` / ``tc`` (iproute2) and ``unshare`` (util-linux): :func:`unavailable` says
why a rig cannot be made, so tests skip with that reason. Every namespace is named
``<prefix>-<i>`` with a prefix unique to this process; :meth:`NetnsRig.close` (also on ``with`` exit, on error or interrupt) kills the
programs it started and deletes the namespaces, which removes their cables.

A launched team on hosts of its own: :func:`launch_team_on_hosts` is
:func:`pipeline.team.launcher.launch_team` (its arguments, its :class:`~pipeline.team.launcher.
TeamRun`) with the team's robots on a rig made for that team's comm edges, every cable capped
at ``rate`` if given (``FORMATION_MATCH_HOSTS`` of the ``zenoh`` transport,
:func:`pipeline.runs.transports.zenoh.team_launcher`, sends every team of a job there). How:

* each robot is its own interpreter, ``python -m pipeline robot`` started in its namespace by
  :meth:`NetnsRig.start` (``ip netns exec``, then its own ``/dev/shm``), not forked from the
  launcher's zygote. The zygote runs in this process's namespace, and so does every robot it
  forks: to be on its host, each child would have to enter its namespace itself between the
  fork and the robot program (``setns``: ``os.setns`` from Python 3.12 on, ``ctypes``
  before) and, for a ``/dev/shm`` of its own, leave the zygote's mount namespace and mount
  one (``unshare``, ``mount``), code of the zygote's own run in every fork. ``ip netns exec``
  and ``unshare`` do exactly that on the command line, as ``bench/team_network.py`` starts its
  robots, at the price of an interpreter start per robot (the robot program imported
  again);
* the observer stays in the launching process, on a Unix socket (the team file's
  ``unixsock-stream//PATH``): a socket file is reached from every network namespace, so
  every robot publishes its whole result to it as on the loopback (the ``--result`` file of
  ``bench/team_network.py`` holds a robot's links only, not the arrays the jobs assemble).
  Nothing is added to this host's own network (no address, no route: rigs of several
  processes do not collide), robots still reach no one but their neighbours (peers do not
  route for others), and only the comm graph's traffic crosses the cables and their caps.
"""

from __future__ import annotations

import contextlib
import itertools
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

__all__ = ["NetnsRig", "unavailable", "remove_stale", "NETEM_MISSING", "read_results", "team_links",
           "kept_links", "conflictive_sets_after", "launch_team_on_hosts", "check_rate"]

#: what this kernel cannot do (stated in reports beside the faults the rig made)
NETEM_MISSING = "netem (packet loss, delay, reordering) is absent from this kernel"


_RIGS = itertools.count()  # rigs made by this process: each its own namespace prefix


def _ip(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    return subprocess.run(["ip", *args], capture_output=True, text=True, check=check)


def unavailable() -> str | None:
    """Why network namespaces cannot be made here (None when they can)."""
    if shutil.which("ip") is None or shutil.which("tc") is None:
        return "iproute2 (ip, tc) is not installed"
    if shutil.which("unshare") is None:
        return "unshare (util-linux) is not installed"
    if os.geteuid() != 0:
        return "making network namespaces needs root"
    name = f"fmprobe-{os.getpid()}"
    r = _ip("netns", "add", name, check=False)
    if r.returncode != 0:
        return f"ip netns add failed: {r.stderr.strip() or r.returncode}"
    _ip("netns", "del", name, check=False)
    return None


_PREFIX = re.compile(r"^fm(\d+)x\d+-\d+$")


def remove_stale() -> list[str]:
    """Delete the namespaces of rigs whose process is gone, and return their names.

    A rig deletes its namespaces when it closes, also on error or Ctrl-C; a process killed
    outright (``SIGKILL``, e.g. a test run stopped by a timeout) cannot, and its namespaces
    stayed until the machine restarted. A rig's names carry its process id
    (``fm<pid>x<k>-<i>``): those of a process that no longer exists are removed. Namespaces
    of live processes, and every other name, are left alone."""
    listed = _ip("netns", "list", check=False).stdout.split("\n")
    gone = []
    for line in listed:
        name = line.split(" ")[0]
        m = _PREFIX.match(name)
        if m is None or int(m.group(1)) == os.getpid():
            continue
        try:
            os.kill(int(m.group(1)), 0)
        except ProcessLookupError:
            _ip("netns", "del", name, check=False)
            gone.append(name)
        except PermissionError:
            pass  # a live process of another user
    return gone


class NetnsRig:
    """``n`` robot hosts, one cable per edge of ``comm_edges`` (module docstring).

    Parameters
    ----------
    n : int — number of robots
    comm_edges : (E, 2) array — the cables
    prefix : str or None — namespace prefix (default unique to this process)
    """

    def __init__(self, n: int, comm_edges, prefix: str | None = None) -> None:
        self.n = int(n)
        self.edges = [tuple(sorted((int(a), int(b))))
                      for a, b in np.asarray(comm_edges, np.int64).reshape(-1, 2)]
        self.prefix = prefix or f"fm{os.getpid()}x{next(_RIGS)}"
        self.procs: dict[int, subprocess.Popen] = {}
        self._made: list[str] = []
        self._caps: dict[tuple[int, int], str] = {}

    # --- names ----------------------------------------------------------------------------
    def ns(self, i: int) -> str:
        return f"{self.prefix}-{int(i)}"

    def address(self, i: int) -> str:
        k = int(i) + 1
        return f"10.78.{k // 250}.{k % 250 + 1}"

    def endpoint(self, i: int, port: int = 7447) -> str:
        """Robot ``i``'s Zenoh endpoint in the team file."""
        return f"tcp/{self.address(i)}:{int(port)}"

    @staticmethod
    def dev(j: int) -> str:
        """The interface, in a robot's namespace, of its cable to robot ``j``."""
        return f"c{int(j)}"

    # --- making and removing --------------------------------------------------------------
    def __enter__(self) -> NetnsRig:
        try:
            self.make()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def make(self) -> None:
        """Create the namespaces, addresses and cables (first removing those a killed
        process left: :func:`remove_stale`)."""
        remove_stale()
        for i in range(self.n):
            _ip("netns", "add", self.ns(i))
            self._made.append(self.ns(i))
            _ip("-n", self.ns(i), "link", "set", "lo", "up")
            _ip("-n", self.ns(i), "addr", "add", f"{self.address(i)}/32", "dev", "lo")
        for a, b in self.edges:
            tmp_a, tmp_b = f"t{os.getpid() % 10000}a{a}x{b}"[:15], f"t{os.getpid() % 10000}b{a}x{b}"[:15]
            _ip("link", "add", tmp_a, "type", "veth", "peer", "name", tmp_b)
            _ip("link", "set", tmp_a, "netns", self.ns(a))
            _ip("link", "set", tmp_b, "netns", self.ns(b))
            _ip("-n", self.ns(a), "link", "set", tmp_a, "name", self.dev(b))
            _ip("-n", self.ns(b), "link", "set", tmp_b, "name", self.dev(a))
            for x, y in ((a, b), (b, a)):
                _ip("-n", self.ns(x), "link", "set", self.dev(y), "up")
                _ip("-n", self.ns(x), "route", "add", f"{self.address(y)}/32", "dev",
                    self.dev(y), "src", self.address(x))

    def close(self) -> None:
        """Kill the programs started here and delete every namespace (and so every cable)."""
        for p in self.procs.values():
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.kill(p.pid, signal.SIGCONT)
                p.kill()
        for p in self.procs.values():
            with contextlib.suppress(Exception):
                p.wait(timeout=10)
        for name in self._made:
            _ip("netns", "del", name, check=False)
        self._made.clear()

    # --- programs -------------------------------------------------------------------------
    def start(self, i: int, argv: list[str], **popen) -> subprocess.Popen:
        """Run ``argv`` on robot ``i``'s host (``ip netns exec``); kept for :meth:`close`.

        The program gets its own ``/dev/shm`` (a private tmpfs in its own mount namespace),
        as on a machine of its own: otherwise Zenoh, finding its peer's shared-memory
        segments, would hand large payloads over shared memory and only a reference would
        cross the cable. The program's pid is that of ``argv`` (each step ``exec`` s)."""
        shell = 'mount -t tmpfs -o size=512m fm-shm /dev/shm && exec "$@"'
        p = subprocess.Popen(["ip", "netns", "exec", self.ns(i), "unshare", "--mount",
                              "--propagation", "private", "sh", "-c", shell, "sh", *argv],
                             **popen)
        self.procs[int(i)] = p
        return p

    def signal(self, i: int, sig: int) -> None:
        """Send ``sig`` to robot ``i``'s program (SIGSTOP freezes the host, SIGCONT resumes,
        SIGKILL kills it)."""
        p = self.procs[int(i)]
        if p.poll() is None:
            os.kill(p.pid, sig)

    # --- faults of the network ------------------------------------------------------------
    def link(self, a: int, b: int, up: bool) -> None:
        """Cable ``(a, b)`` down (partition of that link) or up again (heal)."""
        for x, y in ((a, b), (b, a)):
            _ip("-n", self.ns(x), "link", "set", self.dev(y), "up" if up else "down")
            if up:  # a link set down loses its routes
                _ip("-n", self.ns(x), "route", "replace", f"{self.address(y)}/32", "dev",
                    self.dev(y), "src", self.address(x))

    def cap(self, rate: str, edges=None, burst: str = "32kbit", latency: str = "400ms") -> None:
        """Token-bucket cap ``rate`` (e.g. ``1mbit``) on both ends of each cable (default all)."""
        for a, b in (self.edges if edges is None else edges):
            for x, y in ((a, b), (b, a)):
                subprocess.run(["ip", "netns", "exec", self.ns(x), "tc", "qdisc", "replace",
                                "dev", self.dev(y), "root", "tbf", "rate", rate, "burst", burst,
                                "latency", latency], check=True, capture_output=True, text=True)
            self._caps[(a, b)] = rate

    def qdisc(self, a: int, b: int) -> str:
        """The queueing discipline on robot ``a``'s end of cable ``(a, b)`` (``tc qdisc show``)."""
        return subprocess.run(["ip", "netns", "exec", self.ns(a), "tc", "qdisc", "show", "dev",
                               self.dev(b)], check=True, capture_output=True, text=True).stdout

    # --- what crossed the sockets ---------------------------------------------------------
    def interface_bytes(self, i: int, j: int) -> tuple[int, int]:
        """``(tx, rx)`` bytes of robot ``i``'s end of cable ``(i, j)`` (kernel counters)."""
        r = _ip("-n", self.ns(i), "-s", "-j", "link", "show", "dev", self.dev(j))
        st = json.loads(r.stdout)[0]["stats64"]
        return int(st["tx"]["bytes"]), int(st["rx"]["bytes"])

    def tcp_counters(self, i: int) -> dict[str, int]:
        """Host ``i``'s TCP segments sent and retransmitted since its namespace was made
        (``nstat``; ``{}`` where nstat is missing)."""
        if shutil.which("nstat") is None:
            return {}
        r = subprocess.run(["ip", "netns", "exec", self.ns(i), "nstat", "-a", "-z", "-s",
                            "TcpOutSegs", "TcpRetransSegs"], capture_output=True, text=True)
        return {f[0]: int(f[1]) for f in (line.split() for line in r.stdout.splitlines())
                if len(f) >= 2 and f[0].startswith("Tcp")}

    def link_bytes(self) -> dict[tuple[int, int], int]:
        """Bytes that crossed each cable, both directions (sum of its two ends' tx)."""
        return {(a, b): self.interface_bytes(a, b)[0] + self.interface_bytes(b, a)[0]
                for a, b in self.edges}

    # --- a team on the rig ----------------------------------------------------------------
    def team(self, name: str, data: dict, options: dict | None = None,
             robot_options: dict | None = None):
        """A team whose robot ``i`` listens on host ``i``'s address (no observer)."""
        from pipeline.team.teamfile import DEFAULT_OPTIONS, RobotEntry, Team, parse_team

        robots = [RobotEntry(i, self.endpoint(i)) for i in range(self.n)]
        t = Team(name, robots, np.asarray(self.edges, np.int64), data,
                 {**DEFAULT_OPTIONS, **(options or {})}, dict(robot_options or {}))
        return parse_team(t.to_json())

    def start_robots(self, team, workdir, ids=None, root=None) -> dict:
        """Start ``python -m pipeline robot`` on the hosts of ``ids`` (default all), each
        writing ``workdir/robotI.json`` and its log ``robotI.log``; returns ``{id: json}``."""
        from pipeline.team.teamfile import write_team

        workdir = Path(workdir)
        workdir.mkdir(parents=True, exist_ok=True)
        team_path = workdir / "TEAM.json"
        if not team_path.exists():
            write_team(team_path, team)
        root = Path(root) if root else Path(__file__).resolve().parents[2]
        env = {**os.environ, "PYTHONPATH": str(root), "OMP_NUM_THREADS": "1",
               "OPENBLAS_NUM_THREADS": "1", "PYTHONUNBUFFERED": "1"}
        out = {}
        for i in (range(team.n) if ids is None else ids):
            res = workdir / f"robot{i}.json"
            with open(workdir / f"robot{i}.log", "wb") as log:
                self.start(i, [sys.executable, "-m", "pipeline", "robot", "--team",
                               str(team_path), "--id", str(i), "--result", str(res)],
                           stdout=log, stderr=log, env=env, cwd=str(root))
            out[i] = res
        return out

    def wait_all(self, timeout_s: float) -> dict[int, int | None]:
        """Wait for every program (at most ``timeout_s`` in all); their exit codes (None: still
        running at the limit)."""
        end = time.monotonic() + timeout_s
        for p in self.procs.values():
            with contextlib.suppress(subprocess.TimeoutExpired):
                p.wait(timeout=max(0.0, end - time.monotonic()))
        return {i: p.poll() for i, p in self.procs.items()}


def wait_for_line(path, text: str, timeout_s: float) -> bool:
    """True once ``text`` appears in the file (polled), False after ``timeout_s``."""
    path = Path(path)
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if path.exists() and text in path.read_text(errors="replace"):
            return True
        time.sleep(0.05)
    return False


def read_results(paths: dict) -> dict:
    """The robots' ``--result`` documents that were written, by robot id."""
    return {i: json.loads(Path(p).read_text()) for i, p in paths.items() if Path(p).exists()}


def team_links(res: dict) -> dict:
    """Every link as each end reports it: ``{(i, r, j, s): {robot: (alive, case, round)}}``,
    links stored once with ``i < j``."""
    out: dict = {}
    for i, doc in res.items():
        L = doc["links"]
        for k, r, s, a, c, t in zip(L["link_nbr"], L["link_r"], L["link_s"], L["link_alive"],
                                    L["deleted_case"], L["deleted_round"], strict=True):
            key = (i, r, k, s) if i < k else (k, s, i, r)
            out.setdefault(key, {})[i] = (bool(a), int(c), int(t))
    return out


def kept_links(res: dict):
    """The links kept by every end that wrote a result, as :class:`~pipeline.types.Links`."""
    from pipeline.types import Links

    kept = [k for k, v in team_links(res).items() if all(a for a, _, _ in v.values())]
    return Links([k[0] for k in kept], [k[1] for k in kept], [k[2] for k in kept],
                 [k[3] for k in kept])


def conflictive_sets_after(res: dict) -> int:
    """Association sets of the kept links that hold two features of one camera (Def. 2.4)."""
    from pipeline.consistency.centralized import union_find_conflicts

    m = next(iter(res.values()))["features_per_camera"]
    labels, conflict = union_find_conflicts(m, kept_links(res))
    return int(np.unique(labels[conflict]).size)


#: a ``tc`` rate (``1mbit``, ``256kbit``, ``1.5mbit``, ``100kbps``)
_RATE = re.compile(r"^(\d+(\.\d*)?)(bit|kbit|mbit|gbit|tbit|bps|kbps|mbps|gbps|tbps)$", re.I)


def check_rate(rate: str, what: str) -> str:
    """``rate`` if it is a ``tc`` rate above 0 (``1mbit``, ``256kbit``, ...); else an
    InputError naming ``what``."""
    from pipeline.errors import InputError

    m = _RATE.match(rate)
    if m is None or float(m.group(1)) <= 0:
        raise InputError(f"{what}: {rate!r} is not a bandwidth; give tc's form, a number above 0 "
                         "and its unit, e.g. 1mbit, 256kbit, 10mbit")
    return rate


@contextlib.contextmanager
def _signals_held():
    """Within the block (main thread only) a Ctrl-C or a SIGTERM waits for its end, then
    arrives: namespaces are made or deleted whole, never left half-made by a second Ctrl-C."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    got: list[int] = []
    old = {sig: signal.signal(sig, lambda signum, frame: got.append(signum))
           for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, handler in old.items():
            signal.signal(sig, signal.SIG_DFL if handler is None else handler)
        if got:
            signal.raise_signal(got[0])


def launch_team_on_hosts(team, workdir=None, *, timeout_s: float | None = None,
                         kill: tuple | None = None, log=None, fork: bool = True,
                         stop_at_loss: bool = False, rate: str | None = None):
    """:func:`pipeline.team.launcher.launch_team` of ``team`` with each robot on a host of its
    own (module docstring): a :class:`NetnsRig` of ``team``'s comm edges, every cable capped at
    ``rate`` (``tc`` form, e.g. ``1mbit``; None: uncapped), robot ``i`` listening on
    :meth:`NetnsRig.endpoint` ``(i)`` and the observer on a Unix socket. The returned run's
    ``team`` is the team as started (those endpoints). ``fork`` is not used: every robot is
    its own interpreter. The namespaces are deleted when the team ends, on error, Ctrl-C and
    SIGTERM too (a second one waits until they are gone).

    Raises what ``launch_team`` raises; InputError when the temporary folder's path is too
    long for a Unix socket."""
    import dataclasses

    from pipeline.errors import InputError
    from pipeline.runfolder import make_scratch_folder
    from pipeline.team.launcher import launch_team
    from pipeline.team.teamfile import UNIX_OBSERVER, UNIX_PATH_MAX, RobotEntry, parse_team

    if rate is not None:
        check_rate(rate, "the cables' cap")
    rig = NetnsRig(team.n, team.comm_edges)
    folder = None
    try:
        folder = make_scratch_folder("fm-hosts-")
        sock = folder / "observer.sock"
        if len(str(sock).encode()) > UNIX_PATH_MAX:
            raise InputError(f"the temporary folder {tempfile.gettempdir()!r} is too deep for "
                             f"the observer's Unix socket ({sock}: {UNIX_PATH_MAX} bytes at "
                             "most): set TMPDIR to a shorter folder, e.g. /tmp")
        with _signals_held():
            rig.make()
            if rate is not None and rig.edges:
                rig.cap(rate)
        robots = [RobotEntry(i, rig.endpoint(i)) for i in range(team.n)]
        hosted = parse_team(dataclasses.replace(team, robots=robots,
                                                observer=f"{UNIX_OBSERVER}{sock}").to_json(),
                            team.path)
        return launch_team(hosted, workdir, timeout_s=timeout_s, kill=kill, log=log,
                           stop_at_loss=stop_at_loss, start=rig.start)
    finally:
        with _signals_held():
            rig.close()
            if folder is not None:
                shutil.rmtree(folder, ignore_errors=True)
