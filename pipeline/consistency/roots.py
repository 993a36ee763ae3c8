"""Small sets solved at their roots: the robots' protocol (step 2b of the online stage).

After the bounded label flooding of :mod:`.setlists`, every feature of a set of at most ``B``
features holds the set's whole member list, the smallest id first. The evidence rule
(:mod:`.evidence`) solves such a set when it is conflictive by flooding every member's
*bundle* to every robot of the set, each robot then solving alike. The online stage
(:mod:`.engines.online`) solves more sets per step — every set a step's new links touched, the
conflict-free ones too (its step 2b) — and there the flood was most of a step's bytes. Here
one robot solves each set, its *root* (the robot of the member whose id :func:`spread`
scrambles lowest, :func:`root_of`: every member computes it alike from its list, and the roots
of a step's sets fall on many robots rather than on the one of the smallest ids), and the
others learn only the links it cuts:

1. **Tree** (round 0 on). The root sends a *token* of the set to every robot it shares an
   alive link of the set with. A robot that gets its first token of the set takes the sender
   as its *up* robot (ties in one round: the smallest sender), sends the token on to its own
   set neighbours and sends the bundles of its features of the set up. Every robot of the set
   gets a token (the set is connected over its links), and following up robots ends at the
   root: a robot's up robot got its first token strictly earlier, the root at round 0.
2. **Up.** A robot forwards every bundle it receives for a set (bundles of ``bundle`` format,
   the rule's own: keypoint, alive links with their evidence weights, camera, projection) to
   its up robot, and remembers the sender as a *child* for that set; the root keeps them.
3. **Solve** (at the root, no message). When the root holds a bundle for every member of the
   list it solves :func:`.evidence.solve_set` on them (the sets it completes in one round
   together, :func:`.evidence.solve_sets`) — the rule's Kruskal merge by
   decreasing evidence with the geometric test where every bundle carries a projection — and
   cuts its side of the links it cuts.
4. **Down.** The root sends the cut links (the two ends' global ids) to its children; each
   robot cuts its side of them and sends them on to its own children. Every robot of the set
   sent a bundle up, so it is a child of its up robot and gets the answer.

Which sets (a robot's :class:`~.evidence.EvidenceState`, every robot alike): the small
conflictive sets with ``gather_conflictive`` (the rule's phase 2 then leaves them:
:meth:`~.evidence.EvidenceState.floods_small`), the small conflict-free ones with ``gather_free`` (in a conflict-free
set the merge meets no two features of one image: it cuts only what the geometric test
refutes, and nothing where a bundle carries no projection). A set's robots all know whether
it is conflictive and small (their lists are equal), so all take part or none does.

Same decisions as the rule: the root holds exactly the bundles the rule's flood would give
every robot of the set, and solves the same deterministic function of them (property-tested
against the simulator's batched solution, :func:`.engines.gather.solve_at_roots`; the
simulator runs the robots with :func:`.engines.gather.run_roots`). The cut
links' robots cut their sides alike, so no reject messages. Tracks are not renamed (the online
stage names every set of its step afresh).

Cost: a token over each robot pair of the set sharing a link, once per direction at most
(8 bytes: the set); one hop per bundle and robot on the way up (the rule's bundle bytes); the
cut links, 16 bytes each, once down each tree edge. Rounds: at most about three times the
set's eccentricity from its root (tokens down, bundles up, answer down, pipelined). A robot
holds the bundles passing through it only for the round it forwards them (the root: all of
its set's).

Payloads: ``token`` ``set`` (S,) int64; ``gbundle`` the rule's ``bundle`` payload
(:func:`.evidence.send_bundle_items`); ``cuts`` ``set`` (S,) int64, ``deg`` (S,) int32,
``a``, ``b`` (D,) int64.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pipeline.consistency.evidence import (
    CASE_EVIDENCE,
    EvidenceState,
    bundle_nbytes,
    read_bundle_items,
    send_bundle_items,
    solve_sets,
)
from pipeline.consistency.robot import Robot
from pipeline.transport import Message

__all__ = ["RootsState", "start_roots", "roots_step", "selected_sets", "root_of", "spread",
           "TOKEN", "GBUNDLE", "CUTS"]

TOKEN, GBUNDLE, CUTS = "token", "gbundle", "cuts"


@dataclass
class RootsState:
    """What a robot holds for the protocol.

    Attributes
    ----------
    members : dict ``set -> int`` the set's size (its member list's length)
    own : dict ``set -> {gid -> bundle}`` the bundles of the robot's own features of the set
    nbrs : dict ``set -> list of robots`` it shares an alive link of the set with
    up : dict ``set -> robot`` (absent at the root and before the first token)
    children : dict ``set -> set of robots`` that sent it bundles of the set
    held : dict ``set -> {gid -> bundle}`` at the root, the bundles received
    solved, answered : sets solved here (the root) / whose cuts arrived
    """

    members: dict = field(default_factory=dict)
    own: dict = field(default_factory=dict)
    nbrs: dict = field(default_factory=dict)
    up: dict = field(default_factory=dict)
    children: dict = field(default_factory=dict)
    held: dict = field(default_factory=dict)
    solved: set = field(default_factory=set)
    answered: set = field(default_factory=set)
    held_bytes: int = 0

    def nbytes(self) -> int:
        return int(self.held_bytes + 8 * sum(len(v) for v in self.children.values())
                   + 16 * len(self.members))


#: an odd 64-bit constant (2**64 / golden ratio): multiplying by it is a bijection of the
#: 64-bit integers that scatters consecutive ids (Knuth's multiplicative hashing)
SPREAD = np.uint64(0x9E3779B97F4A7C15)


def spread(gid) -> np.ndarray:
    """The key that chooses roots: ``gid * SPREAD mod 2**64`` (uint64), a fixed bijective
    scrambling of global feature ids, the same on every robot.

    >>> spread([0, 1, 2]).tolist()
    [0, 11400714819323198485, 4354685564936845354]
    """
    return np.asarray(gid, dtype=np.int64).astype(np.uint64) * SPREAD


def root_of(members) -> int:
    """The root feature of a set: its member whose :func:`spread` is smallest (distinct ids
    have distinct keys). Not the smallest id: the robots of a team's first images hold the
    smallest ids of most sets, and each root solves its sets alone (measured: the third
    step of ``run-formation --steps 3 --transport zenoh``, formation d: the robot of the
    first frame solved 884 sets while the other 17 robots spent 27–35 s of their 39 s
    waiting for it).

    >>> root_of([5, 9, 12])
    5
    >>> root_of([1, 2, 3])
    2
    """
    m = np.asarray(members, dtype=np.int64).reshape(-1)
    return int(m[np.argmin(spread(m))])


def selected_sets(robot: Robot, conflictive: bool, free: bool) -> tuple[np.ndarray, np.ndarray]:
    """``(label, size)``, each ``(m,)`` int64: the set (its smallest id) of each own feature
    that takes part, -1 elsewhere, and the length of each own feature's list (its set's size
    where the set is small): small sets (:func:`.setlists.finish_setlists` ran) of two
    features or more, conflictive ones with ``conflictive``, conflict-free ones with
    ``free``."""
    st = robot.setlists
    count = np.bincount(st.r, minlength=robot.m)
    ptr = np.r_[0, np.cumsum(count)]
    first = np.full(robot.m, -1, np.int64)
    has = count > 0
    first[has] = st.ids[ptr[:-1][has]]
    small = robot.active & ~st.large & (count >= 2)
    take = small & ((robot.conflictive & conflictive) | (~robot.conflictive & free))
    return np.where(take, first, -1), count


def start_roots(robot: Robot, send) -> int:
    """Round 0: each robot takes stock of its sets; a root sends its tokens. Returns the
    sets this robot is the root of."""
    ev: EvidenceState = robot.evidence
    st = robot.roots = RootsState()
    label, count = selected_sets(robot, ev.gather_conflictive, ev.gather_free)
    link = np.flatnonzero(robot.link_alive & (label[robot.link_r] >= 0))
    r = robot.link_r[link]
    other = robot.offsets[robot.link_nbr[link]] + robot.link_s[link]
    for f in np.flatnonzero(label >= 0).tolist():
        s = int(label[f])
        st.members[s] = int(count[f])
        on = r == f
        bundle = (ev.keypoints[f].copy(), other[on], ev.link_weight[link[on]], robot.id,
                  ev.projection)
        st.own.setdefault(s, {})[robot.gid0 + f] = bundle
        st.nbrs.setdefault(s, set()).update(robot.link_nbr[link[on]].tolist())
    st.nbrs = {s: sorted(v) for s, v in st.nbrs.items()}
    ptr = np.r_[0, np.cumsum(count)]  # each own feature's member list in setlists.ids
    root = {}  # each set's root feature, from the member list every member holds alike
    for f in np.flatnonzero(label >= 0).tolist():
        root.setdefault(int(label[f]), root_of(robot.setlists.ids[ptr[f]:ptr[f + 1]]))
    rooted = [s for s in st.own if root[s] in st.own[s]]  # the robot of the root feature
    out: dict[int, list] = {}
    for s in rooted:
        st.held[s] = dict(st.own[s])
        st.held_bytes += sum(bundle_nbytes(b) for b in st.own[s].values())
        for j in st.nbrs[s]:
            out.setdefault(j, []).append(s)
    for j in sorted(out):
        send(j, TOKEN, {"set": np.array(out[j], np.int64)})
    _solve_complete(robot, rooted, send, 0)  # a set whose every member is here (one robot)
    robot.measure_memory()
    return len(rooted)


def roots_step(robot: Robot, inbox: list[Message], send, round_: int) -> None:
    """One round: adopt an up robot at the first token, pass tokens and bundles on, solve a
    complete set at its root, pass the cut links down."""
    st: RootsState = robot.roots
    tokens: dict[int, int] = {}
    up_items: dict[int, list] = {}
    down: dict[int, list] = {}
    got_cuts: dict[int, tuple] = {}
    for msg in inbox:
        p = msg.payload
        if msg.kind == TOKEN:
            for s in p["set"].tolist():
                if s in st.own and s not in st.held and s not in st.up:
                    tokens[s] = min(tokens.get(s, msg.src), msg.src)
        elif msg.kind == GBUNDLE:
            for s, g, bundle in read_bundle_items(p):
                st.children.setdefault(s, set()).add(msg.src)
                if s in st.held:
                    if g not in st.held[s]:
                        st.held[s][g] = bundle
                        st.held_bytes += bundle_nbytes(bundle)
                else:
                    up_items.setdefault(s, []).append((g, bundle))
        elif msg.kind == CUTS:
            ends = np.r_[0, np.cumsum(p["deg"])]
            for k, s in enumerate(p["set"].tolist()):
                if s not in st.answered:
                    got_cuts[s] = (p["a"][ends[k]:ends[k + 1]], p["b"][ends[k]:ends[k + 1]])
    out_tokens: dict[int, list] = {}
    for s in sorted(tokens):
        st.up[s] = tokens[s]
        for j in st.nbrs[s]:
            if j != tokens[s]:
                out_tokens.setdefault(j, []).append(s)
        up_items.setdefault(s, []).extend(st.own[s].items())
    for j in sorted(out_tokens):
        send(j, TOKEN, {"set": np.array(out_tokens[j], np.int64)})
    by_up: dict[int, list] = {}
    for s, items in up_items.items():
        by_up.setdefault(st.up[s], []).extend((s, g, b) for g, b in items)
    for j in sorted(by_up):
        send(j, GBUNDLE, send_bundle_items(by_up[j]))
    for s in sorted(got_cuts):
        st.answered.add(s)
        a, b = got_cuts[s]
        _cut_pairs(robot, a, b, round_)
        for j in sorted(st.children.get(s, ())):
            down.setdefault(j, []).append((s, a, b))
    _send_cuts(down, send)
    _solve_complete(robot, list(st.held), send, round_)
    robot.peak_memory_bytes = max(robot.peak_memory_bytes, robot.memory_bytes() + st.nbytes())


def _solve_complete(robot: Robot, sets, send, round_: int) -> None:
    """Solve, cut and answer each of ``sets`` (in that order) whose bundles are all here:
    step 3 then 4 of the protocol. The sets completed in one round are solved together
    (:func:`.evidence.solve_sets`: the same solutions as one at a time)."""
    st: RootsState = robot.roots
    done = [s for s in sets if s not in st.solved and len(st.held[s]) >= st.members[s]]
    for s, (a, b, _, _, cut) in zip(done, solve_sets([st.held[s] for s in done]), strict=True):
        st.solved.add(s)
        st.answered.add(s)
        a, b = a[cut], b[cut]
        _cut_pairs(robot, a, b, round_)
        _send_cuts({j: [(s, a, b)] for j in sorted(st.children.get(s, ()))}, send)
        robot.peak_memory_bytes = max(robot.peak_memory_bytes,
                                      robot.memory_bytes() + st.nbytes())
        st.held_bytes -= sum(bundle_nbytes(x) for x in st.held[s].values())
        st.held[s] = {}  # solved: nothing more to hold


def _send_cuts(down: dict, send) -> None:
    for j in sorted(down):
        items = down[j]
        send(j, CUTS, {"set": np.array([s for s, _, _ in items], np.int64),
                       "deg": np.array([len(a) for _, a, _ in items], np.int32),
                       "a": np.concatenate([a for _, a, _ in items]).astype(np.int64),
                       "b": np.concatenate([b for _, _, b in items]).astype(np.int64)})


def _cut_pairs(robot: Robot, a: np.ndarray, b: np.ndarray, round_: int) -> None:
    """Delete this robot's side of the links ``(a, b)`` (global ids) it holds."""
    a, b = np.asarray(a, np.int64), np.asarray(b, np.int64)
    lo, hi = robot.gid0, robot.gid0 + robot.m
    here_a, here_b = (a >= lo) & (a < hi), (b >= lo) & (b < hi)
    sel = here_a | here_b
    if not sel.any():
        return
    own = np.where(here_a[sel], a[sel], b[sel]) - robot.gid0
    other = np.where(here_a[sel], b[sel], a[sel])
    cam = np.searchsorted(robot.offsets, other, side="right") - 1
    link = robot.find_links(cam, other - robot.offsets[cam])
    ok = link >= 0
    ok[ok] = robot.link_r[link[ok]] == own[ok]
    link = link[ok]
    link = link[robot.link_alive[link]]
    robot.link_alive[link] = False
    robot.deleted_round[link] = int(round_)
    robot.deleted_case[link] = CASE_EVIDENCE
    robot.deleted_iteration[link] = robot.iteration
