"""``TEAM.json``: who is in a robot team, where each robot listens, who talks to whom, what
each robot looks at.

A team file lets every robot run as its own program (``python -m pipeline robot --team
TEAM.json --id I``), on one machine or several. The launcher of ``--transport zenoh`` writes
one; a user may write one by hand. Schema (``version`` 1)::

    {
      "version": 1,
      "name": "formation-d",                      # key-expression prefix of this team
      "robots": [{"id": 0, "endpoint": "tcp/127.0.0.1:7447"}, ...],   # ids 0..n-1, each once
      "comm_edges": [[0, 1], [1, 2], ...],        # undirected, robots talk only along these
      "observer": {"endpoint": "tcp/127.0.0.1:7400"},                 # optional
          # or "unixsock-stream//ABSOLUTE/PATH": a Unix socket, which robots on this machine
          # reach whatever network they are on (robots in network namespaces of their own,
          # pipeline.team.netns); robots always listen on tcp/quic/tls
      "data": {"kind": "formation", "formation": "d", "seed": 0, "size": [640, 480],
               "robots": null, "graph": null}
          or {"kind": "images", "images": ["a.jpg", ...], "intrinsics": [[[fx,0,cx],...], ...],
              "intrinsics_known": [true, ...], "max_size": 1600,
              "intrinsics_source": ["K.txt", ...]}     # optional: where each K came from
              # (K.txt, exif-..., guess: an observer's reconstruction refines EXIF and
              # guessed focal lengths, keeps calibrations)
              # K of the image as the robot uses it (after downscaling to max_size)
          or {"kind": "links", "links": "in.csv", "features_per_camera": [m_0, ...]},
              # "links": ["r0.csv", "r1.csv", ...]: one file per robot, each holding only
              # the rows that touch that robot (a robot reads only its own); a link is in
              # both its robots' files, with one quality (and one weight of "weights"):
              # the two ends compare them before the rule (pipeline.team.robot)
              # optional, both or neither: "keypoints": ["k0.csv", ...], one file per
              # robot, a header "x,y" then one row per feature (m_i rows, pixels), and
              # "cameras": [{"K": [[...]], "R": [[...]], "t": [tx, ty, tz]}, ...], each
              # robot's intrinsics and pose (cam_from_world): with them the robots of a
              # links team know where they look, and option "fusion" fuses their tracks;
              # an entry may instead be {"P": 3x4} (a projection K [R | t] only: the
              # evidence rule's geometric test, no fusion) or null (pose unknown);
              # optional "history": ["h0.npz", ...], one file per robot: an online step's
              # history check after the rule (pipeline.consistency.history.HistoryInputs)
              # optional "weights": ["w0.csv", ...], one file per robot, with "links" a
              # list: a header "weight", then one row per row of the robot's own links file,
              # in its order: each link's local evidence as both robots of the link hold it
              # (pipeline.matching.link_evidence; e.g. clean-db's Sampson error under the
              # pair's stored geometry), in place of the log-odds of its quality; a
              # number each (inf and -inf too, not nan)
          or {"kind": "online-match", "step": 3, "window": 3, "frames": ["f0.npz", ...],
              "store": ["robot-0", ...]}
              # an online step's matching (pipeline.team.online_match): robot I's new frame
              # (frame id step * n + I) and its own folder, where it keeps its window's
              # features between steps; optional "resend": true, the step's matching started
              # again after a robot was lost: each robot sends its neighbours every window
              # frame they match with, whatever it sent them before; optional "void":
              # [frame ids], frames of the window whose robot was lost before publishing
              # them: none stores, sends or matches them
      "options": {"features": "sift", "max_features": 2000, "drop_prob": 0.0, "fault_seed": 0,
                  "round_timeout_s": 30.0, "round_limit_s": 600.0,
                  "start_timeout_s": 60.0, "loss_timeout": 40,
                  "resolution": "evidence",       # a rule of pipeline.consistency.rules,
                                                  # default its DEFAULT_RESOLUTION (a links
                                                  # team: DEFAULT_LINKS_RESOLUTION, as
                                                  # resolve); e.g. "paper" (paper with
                                                  # drop_prob > 0)
                  "merge_radius": null, "contrast_threshold": null, "rootsift": false,
                  "budget_after_merge": false, "threshold_px": 1.0,
                  "wire": "compact"},             # or "plain" (teamfile.WIRE_FORMS)
              # max_features / threshold_px null: scaled with the image size (photos);
              # merge_radius null: that of the resolution, as on the command line (2 px
              # with evidence, 0.5 px with paper)
      "robot_options": {"3": {"drop_prob": 0.2}}  # optional per-robot overrides of "options"
    }                                             # (not "resolution": the team's rule)

A robot reads only its own part of the file: its endpoint and its neighbours' (to connect),
its own ``options`` (``options`` with its ``robot_options``), its own data entry (its image,
its links file), the team size ``n`` (the robots ``1 … n`` of Aragüés et al., Sec. II) and
the comm graph, of which it uses only the edges that touch it: its neighbours ``N_i``.

Relative paths in ``data`` are relative to the team file. Every problem is one
:class:`~pipeline.errors.InputError` line naming the bad value.
"""

from __future__ import annotations

import functools
import ipaddress
import json
import math
import re
import socket
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pipeline import validate
from pipeline.consistency.rules import DEFAULT_RESOLUTION
from pipeline.errors import InputError
from pipeline.matching.methods import (
    FEATURE_METHODS,
    MATCHERS,
    MAX_FEATURES,
    MIN_FEATURES,
    max_features,
)

__all__ = ["Team", "RobotEntry", "load_team", "check_data_files", "write_team", "DEFAULT_OPTIONS",
           "round_timeout_options",
           "DATA_KINDS", "links_file_of", "keypoints_file_of", "weights_file_of",
           "TEAM_ONLY_OPTIONS"]

DATA_KINDS = ("formation", "images", "links", "online-match")
DEFAULT_OPTIONS = {
    "features": "sift",
    "max_features": 2000,
    "merge_radius": None,
    "drop_prob": 0.0,
    "fault_seed": 0,
    # silence after which a neighbour is written off, and the longest one round waits for a
    # neighbour that beats but sends nothing (pipeline.transport.zenoh_transport)
    "round_timeout_s": 30.0,
    "round_limit_s": 600.0,
    "start_timeout_s": 60.0,
    "loss_timeout": 40,
    "fusion": False,
    "resolution": DEFAULT_RESOLUTION,
    "contrast_threshold": None,
    "rootsift": False,
    "budget_after_merge": False,
    "threshold_px": 1.0,
    "wire": "compact",
    "matcher": "opencv",
    # the evidence rule solves its conflictive sets of at most B features (False: leaves
    # them to the caller, the online stage, which gathers them at their roots)
    "solve_small_sets": True,
    # the evidence rule's bundle budget B (None: the team's default, setlists.bundle_budget)
    "bundle_budget": None,
    # the evidence rule's small sets solved at their roots by the robots
    # (pipeline.consistency.roots: the online stage's steps 2 and 2b): the conflictive ones
    # (the rule's own flood then leaves them) and the conflict-free ones
    "gather_conflictive": False,
    "gather_free": False,
    # the caller starts the team again when it loses a robot (an online step): a robot lost
    # in a phase a loss leaves undone (the sets solved at their roots, the history check)
    # ends that work and the robot publishes, naming it lost, instead of failing
    "restarted_on_loss": False,
    # no robot of the team is started again under its id (the launcher's teams): a neighbour
    # whose process ends while starting, before it was heard, is written off at once (its
    # liveliness token gone) rather than after start_timeout_s; off, a robot started again
    # by hand within start_timeout_s still joins
    "closed_at_start": False,
    # Zenoh's shared memory with the robot processes of the same host (a pool per robot:
    # pipeline.transport.zenoh_transport.zenoh_config); off, every message goes over TCP
    "shared_memory": False,
}
#: encodings of what robots send (option ``wire``): ``compact`` — descriptors in compact form
#: (pipeline.matching.packed), features only to the neighbour that matches them, packets
#: zlib-compressed (pipeline.transport.wire); ``plain`` — descriptors as extracted, to every
#: neighbour, packets uncompressed (the earlier encoding, kept to compare the two)
WIRE_FORMS = ("compact", "plain")
#: options that are the team's, not one robot's (every robot must run the same rule, and the
#: fusion stage or none: a robot that skips it ends early and its neighbours cut its links;
#: and extract one kind of descriptor: a neighbour's features are matched as its own kind)
TEAM_ONLY_OPTIONS = ("resolution", "solve_small_sets", "bundle_budget", "gather_conflictive",
                     "gather_free", "fusion", "features", "rootsift")
#: environment variable in which the launcher passes the wall-clock time (``time.time()``) at
#: which it started a robot process, so the robot can report how long its start took
LAUNCHED_AT_ENV = "FORMATION_MATCH_LAUNCHED_AT"
#: environment variable naming a folder: a robot process then runs its robot under cProfile
#: and writes ``<team>-<id>-<pid>.pstats`` there (``bench/team_profile.py`` reads them)
PROFILE_DIR_ENV = "FORMATION_MATCH_PROFILE_DIR"
#: longest round / start timeout a team file may ask for (one day): beyond it a robot would
#: wait for a neighbour that never answers for ever, in practice
MAX_TIMEOUT_S = 86400.0
#: shortest ``round_timeout_s``: a live neighbour beats at most every 0.2 s
#: (:func:`pipeline.transport.zenoh_transport.beat_period`), so below 0.2 s of silence every
#: neighbour is written off by construction (``--round-timeout 0.01``: every robot wrote every
#: neighbour off before a feature crossed and the run ended "done" with no link), and below
#: five beats one late beat on a loaded machine writes a healthy neighbour off
MIN_ROUND_TIMEOUT_S = 1.0
#: most rounds of silence before a neighbour is declared lost (``loss_timeout``)
MAX_LOSS_TIMEOUT = 100_000
#: most features a team file may give one robot (``data.features_per_camera``): a robot holds
#: per-feature arrays (a 10,000,000-feature robot measured 277 MB at construction, before its
#: link tables); ``resolve`` writes compact counts, so this bounds a hand-written file only
MAX_ROBOT_FEATURES = 5_000_000
#: keys a robot entry and each kind of ``data`` may hold
_ROBOT_KEYS = {"id", "endpoint"}
_DATA_KEYS = {"formation": {"kind", "formation", "seed", "size", "robots", "graph"},
              "images": {"kind", "images", "intrinsics", "intrinsics_known", "max_size",
                         "intrinsics_source"},
              "links": {"kind", "links", "features_per_camera", "keypoints", "cameras",
                        "history", "weights"},
              "online-match": {"kind", "step", "window", "frames", "store", "resend",
                               "void"}}
#: a reliable, ordered Zenoh link (the rounds' "nothing lost" rests on it: not udp), host a
#: name, an IPv4 address or a bracketed IPv6 address; the port in digits 0-9 (``\d`` also
#: takes other scripts' digits, which int() reads and Zenoh does not)
_ENDPOINT = re.compile(r"^(tcp|quic|tls)/(\[[0-9A-Fa-f:.]+\]|[^:\s\[\]]+):([0-9]{1,5})$")
_NAME = re.compile(r"^[A-Za-z0-9_.-]+$")


@dataclass
class RobotEntry:
    """One robot: its id and the Zenoh endpoint it listens on (``tcp/HOST:PORT``)."""

    id: int
    endpoint: str


@dataclass
class Team:
    """A parsed, checked team file (see the module docstring)."""

    name: str
    robots: list[RobotEntry]
    comm_edges: np.ndarray
    data: dict
    options: dict = field(default_factory=lambda: dict(DEFAULT_OPTIONS))
    robot_options: dict = field(default_factory=dict)
    observer: str | None = None
    path: Path | None = None

    @property
    def n(self) -> int:
        return len(self.robots)

    def endpoint(self, i: int) -> str:
        return self.robots[i].endpoint

    def neighbours(self, i: int) -> list[int]:
        """Comm-graph neighbours of robot ``i``, sorted."""
        from pipeline.commgraph import neighbour_table

        return sorted(neighbour_table(self.comm_edges, self.n)[int(i)])

    def options_for(self, i: int) -> dict:
        """``options`` with robot ``i``'s overrides applied."""
        return {**self.options, **self.robot_options.get(int(i), {})}

    def shared_terms(self) -> dict:
        """What every robot of the team must read alike from its team file: the team size,
        the comm graph, the kind of data and the team-wide options
        (:data:`TEAM_ONLY_OPTIONS`). Robots started with team files that differ in these would
        run different protocols and never end a phase together; the start handshake compares
        them (:meth:`pipeline.transport.zenoh_transport.ZenohTransport.handshake`)."""
        edges = sorted(sorted(map(int, e)) for e in np.asarray(self.comm_edges).tolist())
        return {"robots": self.n, "comm_edges": edges, "data.kind": self.data.get("kind"),
                **{k: self.options.get(k) for k in TEAM_ONLY_OPTIONS}}

    def check_id(self, i) -> int:
        """The robot id as int; InputError if it is not a robot of this team."""
        try:
            k = int(i)
        except (TypeError, ValueError):
            k = -1
        if str(i).strip() != str(k) or not 0 <= k < self.n:
            raise InputError(f"--id {i}: not a robot of team {self.name!r}; its robots are "
                             f"0..{self.n - 1}")
        return k

    def resolve_path(self, p: str) -> Path:
        q = Path(p)
        return q if q.is_absolute() or self.path is None else self.path.parent / q

    def to_json(self) -> dict:
        out = {"version": 1, "name": self.name,
               "robots": [{"id": r.id, "endpoint": r.endpoint} for r in self.robots],
               "comm_edges": self.comm_edges.tolist(), "data": self.data,
               "options": self.options}
        if self.robot_options:
            out["robot_options"] = {str(k): v for k, v in self.robot_options.items()}
        if self.observer:
            out["observer"] = {"endpoint": self.observer}
        return out


def round_timeout_options(round_timeout_s: float) -> dict:
    """The timeout options of a team whose robots write a silent neighbour off after
    ``round_timeout_s`` seconds (the commands' ``--round-timeout``, given to every team the
    launcher makes, :func:`pipeline.team.launcher.team_round_timeout`): ``round_timeout_s``
    itself, and the start handshake's ``start_timeout_s`` and the longest wait of one round,
    ``round_limit_s``, each at least twice it (their defaults, 60 s and 600 s, otherwise): a
    machine slow enough to leave a neighbour silent that long starts its robots and runs
    their rounds slowly too, and a round never gives up on a neighbour before its silence
    would have written it off.

    >>> round_timeout_options(45)
    {'round_timeout_s': 45.0, 'start_timeout_s': 90.0, 'round_limit_s': 600.0}
    """
    r = float(round_timeout_s)
    return {"round_timeout_s": r,
            "start_timeout_s": max(float(DEFAULT_OPTIONS["start_timeout_s"]), 2.0 * r),
            "round_limit_s": max(float(DEFAULT_OPTIONS["round_limit_s"]), 2.0 * r)}


def _where(path) -> str:
    return f"team file {str(path)!r}" if path else "team"


def parse_team(doc, path: Path | None = None) -> Team:
    """Check a decoded team document and return a :class:`Team` (InputError on any problem)."""
    where = _where(path)
    if not isinstance(doc, dict):
        raise InputError(f"{where}: expected a JSON object at the top, got {type(doc).__name__}")
    unknown = set(doc) - {"version", "name", "robots", "comm_edges", "data", "options",
                          "robot_options", "observer"}
    if unknown:
        raise InputError(f"{where}: unknown key {sorted(unknown)[0]!r}; see the TEAM.json "
                         "schema in the README")
    version = doc.get("version", 1)
    if isinstance(version, bool) or version != 1:  # true == 1 in Python, not in JSON
        raise InputError(f"{where}: version {doc.get('version')!r} is not supported (use 1)")
    name = doc.get("name", "team")
    if not isinstance(name, str) or not _NAME.match(name):
        raise InputError(f"{where}: name {name!r} must be letters, digits, '_', '.', '-'")

    robots_doc = doc.get("robots")
    if not isinstance(robots_doc, list) or len(robots_doc) < 2:
        raise InputError(f"{where}: 'robots' must list at least 2 robots "
                         "({\"id\": I, \"endpoint\": \"tcp/HOST:PORT\"})")
    robots: dict[int, RobotEntry] = {}
    endpoints: dict[str, int] = {}
    # the same listening address written another way (localhost and 127.0.0.1, a host name
    # and its address): robot id by (transport, address, port)
    addresses: dict[tuple[str, str, int], int] = {}
    ports: dict[tuple[str, int], int] = {}  # the first robot on each (transport, port)
    for k, r in enumerate(robots_doc):
        if not isinstance(r, dict) or "id" not in r or "endpoint" not in r:
            raise InputError(f"{where}: robots[{k}] must be an object with 'id' and 'endpoint'")
        if set(r) - _ROBOT_KEYS:
            raise InputError(f"{where}: robots[{k}] has unknown key "
                             f"{sorted(set(r) - _ROBOT_KEYS)[0]!r}; a robot is "
                             "{\"id\": I, \"endpoint\": \"tcp/HOST:PORT\"}")
        rid, ep = r["id"], r["endpoint"]
        if isinstance(rid, bool) or not isinstance(rid, int) or rid < 0:
            raise InputError(f"{where}: robots[{k}] id {rid!r} must be an integer >= 0")
        if rid in robots:
            raise InputError(f"{where}: robot id {rid} is listed twice")
        m = _ENDPOINT.match(ep) if isinstance(ep, str) else None
        if not m or not 0 < int(m.group(3)) < 65536:
            raise InputError(f"{where}: robot {rid} endpoint {ep!r} must look like "
                             f"tcp/HOST:PORT with a port in 1..65535{_endpoint_hint(ep)}")
        if ep in endpoints:
            raise InputError(f"{where}: robots {endpoints[ep]} and {rid} share endpoint {ep!r}; "
                             "each robot listens on its own")
        keys = _endpoint_addresses(m)
        for key in keys:
            other = _same_address(key, addresses, ports)
            if other is not None:
                wild = _ANY in (key[1], *(k[1] for k, r in addresses.items() if r == other))
                how = (f"robot {other}'s {robots[other].endpoint!r} on the same port: a wildcard "
                       "address listens on every address of its machine") if wild else \
                    f"the address of robot {other}'s {robots[other].endpoint!r}"
                raise InputError(f"{where}: robots {other} and {rid} share endpoint {ep!r} "
                                 f"({how}); each robot listens on its own")
        addresses.update(dict.fromkeys(keys, rid))
        for t, _, port in keys:
            ports.setdefault((t, port), rid)
        endpoints[ep] = rid
        robots[rid] = RobotEntry(rid, ep)
    n = len(robots)
    if sorted(robots) != list(range(n)):
        missing = sorted(set(range(n)) - set(robots))
        raise InputError(f"{where}: robot ids must be 0..{n - 1}; id {missing[0]} is missing")

    edges_doc = doc.get("comm_edges")
    if not isinstance(edges_doc, list):
        raise InputError(f"{where}: 'comm_edges' must be a list of [i, j] robot pairs")
    for pair in edges_doc:
        if not (isinstance(pair, list) and len(pair) == 2
                and all(type(v) is int for v in pair)):
            raise InputError(f"{where}: comm edge {pair!r} must be a pair [i, j] of integer "
                             "robot ids")
        if not (0 <= pair[0] < n and 0 <= pair[1] < n) or pair[0] == pair[1]:
            raise InputError(f"{where}: comm edge {pair} must join two different robots "
                             f"0..{n - 1}")
    from pipeline.commgraph import check_comm_edges

    # the graph's one policy for an edge array: an edge listed twice is an error naming it
    e = check_comm_edges(np.array(edges_doc, dtype=np.int64).reshape(-1, 2), n,
                         what=f"{where}: comm edge", noun="robot")
    e = np.unique(e, axis=0) if e.size else np.zeros((0, 2), np.int64)

    data = doc.get("data")
    if not isinstance(data, dict) or data.get("kind") not in DATA_KINDS:
        raise InputError(f"{where}: 'data' must be an object with kind one of "
                         f"{', '.join(DATA_KINDS)}")
    _check_data(data, n, where)

    opts = dict(DEFAULT_OPTIONS)
    if data["kind"] == "links":  # links only, as resolve receives them: its default rule
        from pipeline.consistency.rules import DEFAULT_LINKS_RESOLUTION

        opts["resolution"] = DEFAULT_LINKS_RESOLUTION
    given = doc.get("options") if doc.get("options") is not None else {}
    if not isinstance(given, dict):
        raise InputError(f"{where}: 'options' must be an object")
    _check_options(given, where)
    opts.update(given)
    per = {}
    ro = doc.get("robot_options") if doc.get("robot_options") is not None else {}
    if not isinstance(ro, dict):
        raise InputError(f"{where}: 'robot_options' must be an object {{\"ID\": {{options}}}}")
    for key, val in ro.items():
        try:
            rid = int(key)
        except ValueError:
            rid = -1
        # written as the id itself: ' 1' or '01' beside '1' would silently replace its options
        if key != str(rid) or not 0 <= rid < n or not isinstance(val, dict):
            raise InputError(f"{where}: robot_options key {key!r} must be a robot id 0..{n - 1} "
                             "with an object of options")
        _check_options(val, where)
        fixed = sorted(set(val) & set(TEAM_ONLY_OPTIONS))
        if fixed:
            raise InputError(f"{where}: robot_options[{key!r}] sets {fixed[0]!r}, which is the "
                             "team's (every robot runs the same rule and stages and extracts one kind of "
                             "descriptor); set it under 'options'")
        per[rid] = val
    if data["kind"] == "links" and not all(
            isinstance(c, dict) and "K" in c for c in data.get("cameras") or [None]):
        asks = [k for k, v in [("options", opts), *((f"robot_options[{k!r}]", {**opts, **v})
                                                      for k, v in ro.items())] if v["fusion"]]
        if asks:
            raise InputError(f"{where}: {asks[0]} sets fusion on a links team without "
                             "data.keypoints and every robot's pose in data.cameras (K, R, t); "
                             "fusion needs every robot's keypoints and pose")
    if data["kind"] == "formation":  # the images' size is known: as --merge-radius and --size
        w, h = data.get("size", [640, 480])
        for k, v in [("options", given), *((f"robot_options[{k!r}]", v) for k, v in ro.items())]:
            r = v.get("merge_radius")
            if r is not None and r > min(w, h):
                raise InputError(f"{where}: {k} merge_radius {r!r} must be pixels from 0 to "
                                 f"{min(w, h)}, the shorter side of data.size {w}x{h} (wider, "
                                 "each image's keypoints would be merged across the image)")
    obs = doc.get("observer")
    observer = None
    if obs is not None:
        if not isinstance(obs, dict):
            raise InputError(f"{where}: 'observer' {obs!r} must be an object "
                             "{\"endpoint\": \"tcp/HOST:PORT\"}")
        ep = obs.get("endpoint")
        if isinstance(ep, str) and ep.startswith(UNIX_OBSERVER):
            observer = _unix_observer(where, ep)  # no robot listens on one
        else:
            observer = _tcp_observer(where, ep, endpoints, addresses, ports, robots)
    return Team(name, [robots[i] for i in range(n)], e, data, opts, per, observer, path)


def _tcp_observer(where: str, ep, endpoints: dict, addresses: dict, ports: dict,
                  robots: dict) -> str:
    """An observer endpoint on the network, checked: ``tcp/HOST:PORT`` (or quic, tls) where no
    robot listens."""
    m = _ENDPOINT.match(ep) if isinstance(ep, str) else None
    if not m or not 0 < int(m.group(3)) < 65536:  # port 0: a port of the system's choice
        raise InputError(f"{where}: observer endpoint {ep!r} must look like tcp/HOST:PORT "
                         f"with a port in 1..65535{_endpoint_hint(ep)} (or "
                         f"{UNIX_OBSERVER}/ABSOLUTE/PATH, a Unix socket on the robots' machine)")
    if ep in endpoints:
        raise InputError(f"{where}: observer endpoint {ep!r} is robot {endpoints[ep]}'s")
    for key in _endpoint_addresses(m):
        other = _same_address(key, addresses, ports)
        if other is not None:
            raise InputError(f"{where}: observer endpoint {ep!r} is robot {other}'s "
                             f"({robots[other].endpoint!r}, the same address)")
    return ep


#: how an observer endpoint on a Unix socket starts (``unixsock-stream//tmp/obs.sock``)
UNIX_OBSERVER = "unixsock-stream/"

#: the longest path of a Unix socket, in bytes (``sun_path`` holds 108 with the final NUL)
UNIX_PATH_MAX = 107


def _unix_observer(where: str, ep: str) -> str:
    """An observer endpoint on a Unix socket, checked: an absolute path of at most
    :data:`UNIX_PATH_MAX` bytes (the robots, started anywhere, connect to the same file)."""
    path = ep[len(UNIX_OBSERVER):]
    if not path.startswith("/") or "\0" in path or path.endswith("/"):
        raise InputError(f"{where}: observer endpoint {ep!r}: a Unix socket is "
                         f"{UNIX_OBSERVER}/ABSOLUTE/PATH, the path of a file (the robots may "
                         "run in other folders)")
    if len(path.encode(errors="surrogateescape")) > UNIX_PATH_MAX:
        raise InputError(f"{where}: observer endpoint {ep!r}: a Unix socket's path has at most "
                         f"{UNIX_PATH_MAX} bytes; give a shorter one")
    return ep


def _endpoint_hint(ep) -> str:
    """Why an endpoint that ``_ENDPOINT`` refused may be wrong, for the error's end: udp (not
    reliable), or an IPv6 address written without its brackets (``tcp/::1:7447``, where the
    last ``:`` cannot tell the address from the port)."""
    if not isinstance(ep, str):
        return ""
    if ep.startswith("udp/"):
        return " (udp may lose a round's packet; the rounds need a reliable link)"
    head, _, rest = ep.partition("/")
    host, _, port = rest.rpartition(":")
    if head in ("tcp", "quic", "tls") and port.isdigit() and ":" in host \
            and isinstance(_ip(host), ipaddress.IPv6Address):
        return f" (an IPv6 address goes in brackets: {head}/[{host}]:{port})"
    return ""


#: what a wildcard address (0.0.0.0, ::) is compared as: it listens on every address of the
#: machine, so it takes its port from every other address there
_ANY = "any"
_ANY_IPS = (ipaddress.ip_address("0.0.0.0"), ipaddress.ip_address("::"))


def _same_address(key: tuple[str, str, int], addresses: dict, ports: dict) -> int | None:
    """The robot already listening where ``key`` (transport, address, port) would listen, or
    None: the same address, or either of the two a wildcard on the same transport and port.
    ``addresses`` maps each (transport, address, port) taken to its robot, ``ports`` each
    (transport, port) to the first robot on it: one lookup each, so a team of ``n`` robots
    is checked in ``O(n)``."""
    if key in addresses:
        return addresses[key]
    transport, address, port = key
    if address == _ANY:
        return ports.get((transport, port))
    return addresses.get((transport, _ANY, port))


#: what localhost's addresses are compared as: 127.0.0.1, ::1 and localhost are one (a name
#: may resolve to either); other loopback addresses (127.0.0.2, ...) listen apart
_LOOPBACK = "loopback"
_LOCALHOST_IPS = (ipaddress.ip_address("127.0.0.1"), ipaddress.ip_address("::1"))


def _endpoint_addresses(m: re.Match) -> tuple[tuple[str, str, int], ...]:
    """The (transport, address, port) keys an endpoint matched by ``_ENDPOINT`` listens on.

    The host is resolved with ``socket.getaddrinfo`` (a name that does not resolve stands for
    itself, lower-cased); localhost's addresses (127.0.0.1, ::1) are one key, so
    ``tcp/localhost:P`` and ``tcp/127.0.0.1:P`` collide, while ``tcp/127.0.0.2:P`` (another
    loopback address, which binds apart) does not. quic runs over UDP, tcp and tls over TCP.
    """
    transport = "udp" if m.group(1) == "quic" else "tcp"
    port = int(m.group(3))
    return tuple((transport, a, port) for a in _host_addresses(m.group(2).strip("[]").lower()))


@functools.lru_cache(maxsize=1024)
def _host_addresses(host: str) -> tuple[str, ...]:
    try:
        found = [host] if _ip(host) else [a[4][0] for a in socket.getaddrinfo(
            host, None, type=socket.SOCK_STREAM)]
    except (OSError, UnicodeError, ValueError):
        found = []
    if not found:
        return (_LOOPBACK,) if host == "localhost" or host.endswith(".localhost") else (host,)
    out = []
    for a in found:
        ip = _ip(a.split("%")[0])
        if ip is not None and getattr(ip, "ipv4_mapped", None):
            ip = ip.ipv4_mapped
        key = _LOOPBACK if ip in _LOCALHOST_IPS else _ANY if ip in _ANY_IPS else \
            str(ip) if ip else a
        if key not in out:
            out.append(key)
    return tuple(out)


def _ip(text: str):
    try:
        return ipaddress.ip_address(text)
    except ValueError:
        return None


def _is_int(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _check_data(data: dict, n: int, where: str) -> None:
    from pipeline.validate import render_size

    kind = data["kind"]
    unknown = set(data) - _DATA_KEYS[kind]
    if unknown:
        raise InputError(f"{where}: data of kind {kind} has unknown key {sorted(unknown)[0]!r}; "
                         f"known: {', '.join(sorted(_DATA_KEYS[kind]))}")
    if kind == "formation":
        size = data.get("size", [640, 480])
        if not (isinstance(size, list) and len(size) == 2 and all(_is_int(v) for v in size)):
            raise InputError(f"{where}: data.size {size!r} must be [WIDTH, HEIGHT]")
        render_size(size[0], size[1], f"{size[0]}x{size[1]}", flag=f"{where}: data.size")
        for key in ("formation", "graph"):
            if data.get(key) is not None and not isinstance(data[key], str):
                raise InputError(f"{where}: data.{key} {data[key]!r} must be a name, e.g. "
                                 f"{'d' if key == 'formation' else 'ring'}")
        # the names the robots render (checked here too, so that observe refuses what every
        # robot would refuse, instead of waiting for robots that never start)
        from data_synth import check_formation
        from pipeline.commgraph import GRAPH_KINDS

        if data.get("formation") is not None:
            try:
                check_formation(data["formation"])
            except InputError as exc:
                raise InputError(f"{where}: data.formation: {exc}") from None
        if data.get("graph") is not None and data["graph"] not in GRAPH_KINDS:
            raise InputError(f"{where}: data.graph: unknown graph kind {data['graph']!r}; "
                             f"choose one of {', '.join(GRAPH_KINDS)}")
        seed = data.get("seed", 0)
        if not _is_int(seed) or seed < 0:
            raise InputError(f"{where}: data.seed {seed!r} must be an integer >= 0")
        validate.seed(seed, f"{where}: data.seed")  # run-formation --seed's range
        if data.get("robots") is not None:
            if not _is_int(data["robots"]):
                raise InputError(f"{where}: data.robots {data['robots']!r} must be an integer "
                                 f"from 2 to {validate.MAX_ROBOTS} or null (the formation's 6)")
            validate.robots(data["robots"], f"{where}: data.robots")  # run-formation --robots'
        expected = 6 if data.get("robots") is None else data["robots"]
        if expected != n:
            raise InputError(f"{where}: data describes {expected} robots but 'robots' lists {n}")
    elif kind == "images":
        imgs = data.get("images")
        if not isinstance(imgs, list) or len(imgs) != n or not all(isinstance(p, str) for p in imgs):
            raise InputError(f"{where}: data.images must list one image path per robot ({n})")
        K = data.get("intrinsics")
        if K is not None:
            if not isinstance(K, list) or len(K) != n:
                raise InputError(f"{where}: data.intrinsics must give one 3x3 K (or null) per robot")
            for i, k in enumerate(K):
                if k is not None and not (isinstance(k, list) and len(k) == 3 and all(
                        isinstance(row, list) and len(row) == 3 and all(map(_is_number, row))
                        for row in k)):
                    raise InputError(f"{where}: data.intrinsics[{i}] must be a 3x3 matrix of "
                                     "finite numbers or null")
                if k is not None and not _pinhole(k):
                    raise InputError(f"{where}: data.intrinsics[{i}] K = {k} is not a pinhole "
                                     f"matrix with positive focal lengths ({_pinhole_rule()}), "
                                     "as a K.txt gives it")
        known = data.get("intrinsics_known")
        if known is not None and not (isinstance(known, list) and len(known) == n
                                      and all(isinstance(v, bool) for v in known)):
            raise InputError(f"{where}: data.intrinsics_known must list {n} true/false values "
                             "or be null")
        src = data.get("intrinsics_source")
        if src is not None and not (isinstance(src, list) and len(src) == n
                                    and all(isinstance(v, str) for v in src)):
            raise InputError(f"{where}: data.intrinsics_source must list {n} names (K.txt, "
                             "exif-35mm, guess, ...) or be null")
        ms = data.get("max_size")
        if ms is not None and (not _is_int(ms) or ms < 0):
            raise InputError(f"{where}: data.max_size {ms!r} must be a number of pixels >= 0 "
                             "(0: full size) or null")
    elif kind == "online-match":
        for key in ("step", "window"):
            v = data.get(key)
            if not _is_int(v) or v < (0 if key == "step" else 1):
                raise InputError(f"{where}: data.{key} {v!r} must be an integer >= "
                                 f"{0 if key == 'step' else 1}")
        if not isinstance(data.get("resend", False), bool):
            raise InputError(f"{where}: data.resend {data['resend']!r} must be true or false "
                             "(true: the step's matching started again; each robot sends its "
                             "window frames again)")
        void = data.get("void", [])
        step, window = data["step"], data["window"]
        if not (isinstance(void, list) and all(_is_int(f) and 0 <= f < step * n
                                               and f // n > step - window for f in void)):
            raise InputError(f"{where}: data.void {void!r} must list frame ids of the window's "
                             f"earlier steps ({max(0, step - window + 1) * n} to "
                             f"{step * n - 1}: frame = step * {n} + robot), the frames lost "
                             "before they were published")
        for key, what in (("frames", "frame file (its camera's new frame)"),
                          ("store", "folder (its features between steps)")):
            v = data.get(key)
            if not (isinstance(v, list) and len(v) == n and all(isinstance(x, str) for x in v)):
                raise InputError(f"{where}: data.{key} must list {n} paths, one {what} per "
                                 "robot")
    elif kind == "links":
        lk = data.get("links")
        if not (isinstance(lk, str) or (isinstance(lk, list) and len(lk) == n
                                        and all(isinstance(p, str) for p in lk))):
            raise InputError(f"{where}: data.links must be the path of a links CSV file, or "
                             f"a list of {n} paths, one per robot (each its own rows)")
        fpc = data.get("features_per_camera")
        if not isinstance(fpc, list) or len(fpc) != n or not all(
                _is_int(v) and 0 <= v <= MAX_ROBOT_FEATURES for v in fpc):
            raise InputError(f"{where}: data.features_per_camera must list {n} counts in "
                             f"0..{MAX_ROBOT_FEATURES} (a robot's memory follows its count)")
        _check_links_cameras(data, n, where)
        hist = data.get("history")
        if hist is not None and not (isinstance(hist, list) and len(hist) == n
                                     and all(isinstance(p, str) for p in hist)):
            raise InputError(f"{where}: data.history must list {n} paths, one history file "
                             "per robot (an online step's check), or be absent")
        weights = data.get("weights")
        if weights is not None and not (isinstance(lk, list) and isinstance(weights, list)
                                        and len(weights) == n
                                        and all(isinstance(p, str) for p in weights)):
            raise InputError(f"{where}: data.weights must list {n} paths, one weights file per "
                             "robot (a row per row of its own links file), with data.links a "
                             "list of one links file per robot; or be absent")


def _pinhole(K) -> bool:
    """``K`` (a 3x3 of finite numbers) is a pinhole matrix: rows ``fx s cx``, ``0 fy cy``,
    ``0 0 1`` with ``fx, fy > 0`` at most ``MAX_FOCAL_RATIO`` times apart and
    ``|s| <= MAX_SKEW_FRACTION * fx`` (what :func:`pipeline.inputs.photos.read_k_txt`
    accepts)."""
    from pipeline.inputs.photos import MAX_FOCAL_RATIO, MAX_SKEW_FRACTION

    K = np.asarray(K, dtype=np.float64)
    return bool(np.allclose(K[2], [0.0, 0.0, 1.0]) and K[1, 0] == 0.0 and K[0, 0] > 0
                and K[1, 1] > 0 and 1.0 / MAX_FOCAL_RATIO <= K[1, 1] / K[0, 0] <= MAX_FOCAL_RATIO
                and abs(K[0, 1]) <= MAX_SKEW_FRACTION * K[0, 0])


def _pinhole_rule() -> str:
    """What :func:`_pinhole` asks, in the words of the error that refuses a matrix."""
    from pipeline.inputs.photos import MAX_FOCAL_RATIO, MAX_SKEW_FRACTION

    return (f"rows 'fx s cx', '0 fy cy', '0 0 1', fx and fy > 0 and at most "
            f"{MAX_FOCAL_RATIO:g} times apart, the skew |s| at most {MAX_SKEW_FRACTION:g} x fx")


def _is_matrix(v, rows: int, cols: int) -> bool:
    return isinstance(v, list) and len(v) == rows and all(
        isinstance(r, list) and len(r) == cols and all(map(_is_number, r)) for r in v)


def _check_links_cameras(data: dict, n: int, where: str) -> None:
    """``data.keypoints`` and ``data.cameras`` of a links team: both or neither, one entry per
    robot (module docstring)."""
    kp, cams = data.get("keypoints"), data.get("cameras")
    if (kp is None) != (cams is None):
        raise InputError(f"{where}: data.{'keypoints' if cams is None else 'cameras'} is "
                         f"given without data.{'cameras' if cams is None else 'keypoints'}; "
                         "a links team's robots need both (their keypoints and their poses) "
                         "or neither")
    if kp is None:
        return
    if not (isinstance(kp, list) and len(kp) == n and all(isinstance(p, str) for p in kp)):
        raise InputError(f"{where}: data.keypoints must list {n} paths, one keypoints file "
                         "per robot (header x,y, one row per feature)")
    if not isinstance(cams, list) or len(cams) != n:
        raise InputError(f"{where}: data.cameras must list {n} cameras, one per robot "
                         '({"K": 3x3, "R": 3x3, "t": [tx, ty, tz]})')
    for i, c in enumerate(cams):
        if c is None:  # a robot of unknown pose
            continue
        if isinstance(c, dict) and set(c) == {"P"}:
            if not _is_matrix(c["P"], 3, 4):
                raise InputError(f"{where}: data.cameras[{i}].P must be a 3x4 matrix of finite "
                                 "numbers (K [R | t])")
            # no finite camera: its robot's geometric test would refuse every point through it
            if np.linalg.matrix_rank(np.asarray(c["P"], dtype=np.float64)[:, :3]) < 3:
                raise InputError(f"{where}: data.cameras[{i}].P: its left 3x3 block (K R) is "
                                 "singular; give the camera's K [R | t], or null where its pose "
                                 "is unknown")
            continue
        if not isinstance(c, dict) or set(c) != {"K", "R", "t"}:
            keys = sorted(set(c) - {"K", "R", "t"}) if isinstance(c, dict) else []
            raise InputError(f"{where}: data.cameras[{i}] must be an object with exactly "
                             '"K", "R" and "t" (a pose), exactly "P" (a projection) or null '
                             "(unknown)" + (f"; unknown key {keys[0]!r}" if keys else ""))
        for key, shape in (("K", (3, 3)), ("R", (3, 3))):
            if not _is_matrix(c[key], *shape):
                raise InputError(f"{where}: data.cameras[{i}].{key} must be a 3x3 matrix of "
                                 "finite numbers")
            if np.linalg.matrix_rank(np.asarray(c[key], dtype=np.float64)) < 3:
                raise InputError(f"{where}: data.cameras[{i}].{key} is singular; give the "
                                 "camera's " + ("intrinsics (an invertible K)" if key == "K"
                                                else "rotation (cam_from_world)"))
            if key == "K" and not _pinhole(c[key]):
                raise InputError(f"{where}: data.cameras[{i}].K = {c[key]} is not a pinhole "
                                 f"matrix with positive focal lengths ({_pinhole_rule()}), as a "
                                 "K.txt gives it")
        if not (isinstance(c["t"], list) and len(c["t"]) == 3 and all(map(_is_number, c["t"]))):
            raise InputError(f"{where}: data.cameras[{i}].t {c['t']!r} must be 3 finite numbers")


def _check_options(opts: dict, where: str) -> None:
    unknown = set(opts) - set(DEFAULT_OPTIONS)
    if unknown:
        raise InputError(f"{where}: unknown option {sorted(unknown)[0]!r}; known: "
                         f"{', '.join(DEFAULT_OPTIONS)}")
    p = opts.get("drop_prob", 0.0)
    if not _is_number(p) or not 0.0 <= p < 1.0:  # true/false are no probabilities
        raise InputError(f"{where}: option drop_prob {p!r} must be in [0, 1)")
    for k in ("round_timeout_s", "round_limit_s", "start_timeout_s"):
        v = opts.get(k, 1.0)
        if not _is_number(v) or not 0 < v <= MAX_TIMEOUT_S:
            raise InputError(f"{where}: option {k} {v!r} must be a number of seconds in "
                             f"(0, {MAX_TIMEOUT_S:g}]")
    silence = opts.get("round_timeout_s", MIN_ROUND_TIMEOUT_S)
    if silence < MIN_ROUND_TIMEOUT_S:
        raise InputError(f"{where}: option round_timeout_s {silence!r} is shorter than "
                         f"{MIN_ROUND_TIMEOUT_S:g} s: a live neighbour beats every 0.2 s at "
                         "most, so every robot would write its neighbours off as silent; give "
                         "a few seconds or more, e.g. 30 (the default)")
    v = opts.get("max_features")
    if v is not None:  # None: scaled with the image size (photo_max_features)
        if not _is_int(v):
            raise InputError(f"{where}: option max_features {v!r} must be an integer in "
                             f"{MIN_FEATURES}..{MAX_FEATURES} or null")
        max_features(v, f"{where}: option max_features", auto="null")  # --max-features'
    v = opts.get("loss_timeout", 8)
    if not _is_int(v) or not 1 <= v <= MAX_LOSS_TIMEOUT:
        raise InputError(f"{where}: option loss_timeout {v!r} must be an integer in "
                         f"1..{MAX_LOSS_TIMEOUT}")
    for k in ("threshold_px", "contrast_threshold"):
        v = opts.get(k)
        if v is not None and (not _is_number(v) or not v > 0):
            raise InputError(f"{where}: option {k} {v!r} must be a finite number > 0 or null")
    budget = opts.get("bundle_budget")
    if budget is not None and (not _is_int(budget) or budget < 1):
        raise InputError(f"{where}: option bundle_budget {budget!r} must be an integer >= 1 "
                         "(the largest set the evidence rule bundles) or null (the team's "
                         "default)")
    seed = opts.get("fault_seed", 0)
    if not _is_int(seed) or seed < 0:
        raise InputError(f"{where}: option fault_seed {seed!r} must be an integer >= 0")
    validate.seed(seed, f"{where}: option fault_seed")  # run-formation --fault-seed's range
    r = opts.get("merge_radius")
    if r is not None and (not _is_number(r) or r < 0):
        raise InputError(f"{where}: option merge_radius {r!r} must be a finite number of "
                         "pixels >= 0")
    for k in ("fusion", "rootsift", "budget_after_merge", "solve_small_sets", "gather_conflictive",
              "gather_free", "shared_memory", "restarted_on_loss", "closed_at_start"):
        if not isinstance(opts.get(k, False), bool):
            raise InputError(f"{where}: option {k} {opts[k]!r} must be true or false")
    if opts.get("wire", "compact") not in WIRE_FORMS:
        raise InputError(f"{where}: option wire {opts['wire']!r} must be one of "
                         f"{', '.join(WIRE_FORMS)}")
    method = opts.get("features", "sift")
    if method not in FEATURE_METHODS:
        raise InputError(f"{where}: option features {method!r} must be one of "
                         f"{', '.join(FEATURE_METHODS)}")
    if opts.get("matcher", "opencv") not in MATCHERS:
        raise InputError(f"{where}: option matcher {opts['matcher']!r} must be one of "
                         f"{', '.join(MATCHERS)}")
    from pipeline.consistency.rules import rule_names

    if opts.get("resolution", DEFAULT_RESOLUTION) not in rule_names():
        raise InputError(f"{where}: option resolution {opts['resolution']!r} must be one of "
                         f"{', '.join(rule_names())}")


def load_team(path) -> Team:
    """Read and check a team file; InputError (one line) on a missing or malformed file."""
    from pipeline.outputs import require_input_file

    p = Path(path)
    if not p.exists():
        raise InputError(f"team file {str(p)!r} not found")
    require_input_file(p, "team file")
    raw = p.read_bytes()
    try:
        # utf-8-sig: a file saved by Notepad starts with a byte order mark, which json refused
        # ("Unexpected UTF-8 BOM (decode using utf-8-sig)")
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        utf16 = " (a UTF-16 file)" if raw[:2] in (b"\xff\xfe", b"\xfe\xff") else ""
        raise InputError(f"team file {str(p)!r} is not valid JSON: not UTF-8 text{utf16} (byte "
                         f"0x{raw[exc.start]:02x} at offset {exc.start}); save it as UTF-8") \
            from None
    try:
        doc = json.loads(text)
    except ValueError as exc:
        raise InputError(f"team file {str(p)!r} is not valid JSON: {exc}") from None
    except RecursionError:
        raise InputError(f"team file {str(p)!r} nests lists or objects too deeply to be a "
                         "team file; see the TEAM.json schema in the README") from None
    return parse_team(doc, p)


def check_data_files(team: Team, i: int) -> list[tuple[str, Path]]:
    """Check, before a robot opens its session, what robot ``i`` will read; return the files.

    Formation data: the formation, graph, seed and robot count are known to
    :mod:`data_synth` (nothing is rendered). Images: robot ``i``'s image file exists. Links:
    the links file exists.

    Returns
    -------
    list of ``(what, path)`` — the data files robot ``i`` reads (to keep outputs off them)

    Raises
    ------
    InputError
        Naming the bad value or the missing file.
    """
    from pipeline.outputs import require_input_file

    data = team.data
    where = _where(team.path)
    if data["kind"] != "links":
        from pipeline.matching.features import check_method

        check_method(team.options_for(i)["features"])
    if data["kind"] == "formation":
        import data_synth

        data_synth.formation_edges(data.get("formation", "d"), data.get("seed", 0),
                                   data.get("robots"), data.get("graph"))
        return []
    if data["kind"] == "images":
        path = team.resolve_path(data["images"][i])
        return [(f"data.images[{i}] of the team file",
                 require_input_file(path, f"{where}: data.images[{i}]"))]
    if data["kind"] == "online-match":
        path = team.resolve_path(data["frames"][i])
        return [(f"data.frames[{i}] of the team file",
                 require_input_file(path, f"{where}: data.frames[{i}]"))]
    path, own = links_file_of(team, i)
    what = f"data.links[{i}]" if own else "data.links"
    files = [(f"{what} of the team file", require_input_file(path, f"{where}: {what}"))]
    kp = keypoints_file_of(team, i)
    if kp is not None:
        files.append((f"data.keypoints[{i}] of the team file",
                      require_input_file(kp, f"{where}: data.keypoints[{i}]")))
    if team.data.get("history") is not None:
        hp = team.resolve_path(team.data["history"][int(i)])
        files.append((f"data.history[{i}] of the team file",
                      require_input_file(hp, f"{where}: data.history[{i}]")))
    wp = weights_file_of(team, i)
    if wp is not None:
        files.append((f"data.weights[{i}] of the team file",
                      require_input_file(wp, f"{where}: data.weights[{i}]")))
    return files


def links_file_of(team: Team, i: int) -> tuple[Path, bool]:
    """Robot ``i``'s links file and whether it is its own (``data.links`` a list of one file
    per robot) rather than the team's shared one."""
    lk = team.data["links"]
    if isinstance(lk, list):
        return team.resolve_path(lk[int(i)]), True
    return team.resolve_path(lk), False


def keypoints_file_of(team: Team, i: int) -> Path | None:
    """Robot ``i``'s keypoints file of a links team (``data.keypoints``), or None."""
    kp = team.data.get("keypoints")
    return None if kp is None else team.resolve_path(kp[int(i)])


def weights_file_of(team: Team, i: int) -> Path | None:
    """Robot ``i``'s weights file of a links team (``data.weights``), or None."""
    w = team.data.get("weights")
    return None if w is None else team.resolve_path(w[int(i)])


def write_team(path, team: Team) -> Path:
    """Write ``team`` as JSON atomically; return the path."""
    from pipeline.runfolder import atomic_file

    p = Path(path)
    with atomic_file(p) as f:  # a new temporary name: nothing beside it is written through
        f.write(json.dumps(team.to_json(), indent=1))
    return p
