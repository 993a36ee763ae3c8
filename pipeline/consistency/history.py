"""The history check of an online step run by the robots (step 3, :mod:`.engines.online_history`).

After a step's rule has cut, a set the step's new links formed may still hold one image twice:
two window features of one frame (the rule cut a history link, which stands for a retired
piece and cannot go), or two retired pieces that share a retired frame, which no window
image shows. The online stage's record (:class:`.engines.online.OnlineAssociation`) finds
these sets and repairs them by :func:`rebuild`; here the stage's robots — one per window
frame, the cameras of the step's sub-problem — find and repair them themselves, exchanging
messages only over the sub-problem's links. Each frame's robot holds (:class:`HistoryInputs`):
its frame's global feature ids, team robot and step; for each row of its link table the
link's id and quality (-1 for a history link) and whether a history link joins the row's two
features; its *border links* (kept links from its window features into retired pieces: id,
feature, piece, quality) and the *retired entries* of the pieces they reach (the step runs of
each team robot's frames in the piece, :mod:`.engines.online`).

Phases, each run until nothing is in flight (the termination wave ends it for a robot alone;
its bits say, every robot alike, whether the next phase is needed):

1. **Names** (``hlab``). The sets after the rule's cuts are the components of the kept real
   links and every history link (a cut history link stays: it stands for a piece). Only a
   set that reaches a retired piece can be bad: two pieces need one, and a frame twice needs
   a *rejoining* row, one the rule cut that a history link doubles (the rule leaves the
   components of the links it kept conflict-free), whose ends a history link ties to a
   piece. A piece belongs to one set (the history links chain the window features it
   reaches), so a set's smallest piece names it. Each feature with a border link starts
   with the two smallest pieces its border links reach, every other feature with none; the
   two smallest pieces heard flood over those links (label flooding, as :mod:`.labels`, from
   those features only: a set without a piece sends nothing) with a flag, raised where a
   robot holds two features naming one piece (its frame twice: a conflict a robot sees
   alone) and ORed along. At the end every feature of such a set holds the set's name,
   whether it has two pieces or more, and its flag: a set with two pieces or more, or
   flagged, is *examined*; its *root* is the robot holding the head of its first piece's
   chain (the smallest window feature the piece's border links reach, which its robot
   knows: ``border_head``). Bits: ``MANY``, ``BAD``.
2. **Echo** (``htok``, ``hecho``; examined sets). Segall's echo algorithm from each examined
   set's root over the set's links: a robot takes the sender of its first token as its
   parent and sends tokens on; it answers its parent once every other neighbour answered
   (by an echo, as its child, or by a token of its own), with the retired entries (step runs
   ``(piece, robot, lo, hi)``) of its own and its subtree's pieces. The root then holds the
   set's entries: the set is *bad* if it is flagged or one team robot has overlapping runs
   (one retired frame in two pieces). Bits: ``BAD``.
3. **Repair** (``hgo``, ``hup``, ``hcut``; bad sets). The root asks down its tree; each robot
   sends up, once its children did, its and its subtree's *halves* of the set's open links:
   one per kept real link of its features (its end: the feature's global id, team robot and
   step) and one per border link (with its piece; quality as the bits of its float64). The
   root computes :func:`rebuild` — the same deterministic function the record computes — on
   the set's links and entries, and the links it skips go down the tree; each robot cuts its
   side of them: its rows and its border links (:attr:`HistoryState.cut`; the step's record
   applies them, reason ``history``).

Same decisions as the record's check (:meth:`.engines.online_history.HistoryCheck.
_history_check` with ``overturn``, the default): the sets are the same components, a set is
bad under the same two conditions (runs of one robot in one piece never overlap, so overlap
needs two pieces; a window frame's single step never overlaps a retired run, so a set with
one piece needs no entries to be repaired), and :func:`rebuild` gets the same groups and
links in the same order. Property-tested against the record's check
(``tests/pipeline/consistency/engines/test_history_run.py``).

Costs: counted by the transport as every message. Phase 1 is a label flooding over the
links of the sets that reach a piece (13 bytes per feature and change while piece names fit
in an int32, 21 beyond); phases 2 and 3 cross
each link of an examined set once or twice with a token, and carry each entry and each half
one hop per tree edge up to the root (32 and 48 bytes, plus 8 for the set's name), the cut
links down (16 bytes each per tree edge).

Payloads: ``hlab`` ``s`` (K,) int32 (the receiver's feature), ``p`` (K, 2) int32, or int64
once a piece name does not fit (its two smallest pieces heard, -1 where fewer), ``flag`` (K,)
uint8; ``htok``,
``hgo`` ``set`` (S,) int64; ``hecho``, ``hup`` ``set`` (S,) the sets answered, ``lab`` (K,),
``item`` (K, 4) entries / (K, 6) halves; ``hcut`` ``lab``, ``id`` (K,) int64.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pipeline.consistency.robot import Robot
from pipeline.transport import Message

__all__ = ["HistoryInputs", "HistoryState", "equip_history", "rebuild", "rebuild_halves",
           "start_names", "names_step", "finish_names", "start_echo", "echo_step",
           "finish_echo", "start_repair", "repair_step", "own_entries", "own_links",
           "runs_by_robot", "overlapping_runs", "PHASES",
           "HLAB", "HTOK", "HECHO", "HGO", "HUP", "HCUT", "MANY", "BAD", "NONE"]

HLAB, HTOK, HECHO, HGO, HUP, HCUT = "hlab", "htok", "hecho", "hgo", "hup", "hcut"
#: wave bits of phase 1 (beside the reliable channel's ``LOST``): a set with two pieces or
#: more, a set flagged (phase 2 runs); of phase 2: a bad set (phase 3 runs)
MANY, BAD = 8, 16
#: no piece (phase 1): a feature no piece reached; its set cannot be bad, it takes no part
NONE = np.iinfo(np.int64).max


@dataclass
class HistoryInputs:
    """What one window frame's robot holds for the check (module docstring).

    ``gid0``: the online global id of the frame's feature 0; ``robot``, ``step``: the team
    robot that took the frame and its step. Rows (any order; matched to the robot's link
    table by ``(row_nbr, row_s)``): ``row_id`` the link's id (-1: a history link),
    ``row_quality``, ``row_hist`` (a history link joins the row's two features). Border links:
    ``border_r`` (own feature), ``border_piece``, ``border_id``, ``border_quality``,
    ``border_head`` (its feature is the smallest window feature the piece's border links
    reach: the head of the piece's chain of history links). Entries
    of those pieces: ``entry_piece``, ``entry_robot``, ``entry_lo``, ``entry_hi``.
    """

    gid0: int
    robot: int
    step: int
    row_nbr: np.ndarray
    row_s: np.ndarray
    row_id: np.ndarray
    row_quality: np.ndarray
    row_hist: np.ndarray
    border_r: np.ndarray
    border_piece: np.ndarray
    border_id: np.ndarray
    border_quality: np.ndarray
    border_head: np.ndarray
    entry_piece: np.ndarray
    entry_robot: np.ndarray
    entry_lo: np.ndarray
    entry_hi: np.ndarray

    ARRAYS = ("row_nbr", "row_s", "row_id", "row_quality", "row_hist", "border_r",
              "border_piece", "border_id", "border_quality", "border_head", "entry_piece",
              "entry_robot",
              "entry_lo", "entry_hi")

    def to_arrays(self) -> dict:
        """The inputs as named arrays (e.g. one ``.npz`` file per robot process)."""
        out = {k: np.asarray(getattr(self, k)) for k in self.ARRAYS}
        out["head"] = np.array([self.gid0, self.robot, self.step], np.int64)
        return out

    @classmethod
    def from_arrays(cls, arrays) -> HistoryInputs:
        head = np.asarray(arrays["head"], np.int64)
        return cls(int(head[0]), int(head[1]), int(head[2]),
                   **{k: np.asarray(arrays[k]) for k in cls.ARRAYS})


@dataclass
class HistoryState:
    """A robot's state of the check. Rows of its link table: ``row_id``, ``row_quality``,
    ``row_hist``; ``conn`` the rows that join sets (kept real rows, history rows). Phase 1,
    per own feature: ``label`` / ``second`` its two smallest pieces heard (``label`` names the
    set), ``flag``; then per set
    ``checked`` (two pieces or more, or flagged), ``flagged``, ``roots`` (this robot holds the
    root's feature). Phase 2, per set: ``nbrs``, ``parent``, ``children``, ``waiting``,
    ``collected``, ``done``; at a root ``entries`` and ``bad``. Phase 3: ``pending``,
    ``halves``; ``cut`` the link ids this robot cut (its rows and border links)."""

    inp: HistoryInputs
    row_id: np.ndarray
    row_quality: np.ndarray
    row_hist: np.ndarray
    conn: np.ndarray = None
    label: np.ndarray = None
    second: np.ndarray = None
    flag: np.ndarray = None
    checked: set = field(default_factory=set)
    flagged: set = field(default_factory=set)
    roots: set = field(default_factory=set)
    nbrs: dict = field(default_factory=dict)
    parent: dict = field(default_factory=dict)
    children: dict = field(default_factory=dict)
    waiting: dict = field(default_factory=dict)
    collected: dict = field(default_factory=dict)
    done: set = field(default_factory=set)
    entries: dict = field(default_factory=dict)
    bad: set = field(default_factory=set)
    pending: dict = field(default_factory=dict)
    halves: dict = field(default_factory=dict)
    cut: list = field(default_factory=list)

    def nbytes(self) -> int:
        held = sum(len(it) for d in (self.collected, self.halves) for v in d.values()
                   for it in v) + sum(4 * len(v) for v in self.entries.values())
        per_feature = 0 if self.label is None else 2 * self.label.nbytes + self.flag.nbytes
        return int(sum(a.nbytes for a in (self.row_id, self.row_quality, self.row_hist))
                   + 8 * held + per_feature + 8 * sum(len(v) for v in self.nbrs.values()))


def equip_history(robot: Robot, inp: HistoryInputs) -> None:
    """Give ``robot`` its inputs (``robot.history``). Raises ``ValueError`` if a row of the
    inputs is not in its link table or a row of the table has no input (a bug, not a user's
    input)."""
    k = len(robot.link_key)
    pos = robot.find_links(np.asarray(inp.row_nbr, np.int64), np.asarray(inp.row_s, np.int64))
    if (pos < 0).any() or len(pos) != k or len(np.unique(pos)) != k:
        raise ValueError(f"robot {robot.id}: the history inputs name {len(pos)} rows, its "
                         f"link table holds {k}")
    row_id = np.empty(k, np.int64)
    row_q = np.empty(k, np.float64)
    row_h = np.empty(k, bool)
    row_id[pos] = inp.row_id
    row_q[pos] = inp.row_quality
    row_h[pos] = inp.row_hist
    robot.history = HistoryState(inp, row_id, row_q, row_h)


# ---------------------------------------------------------------------- phase 1: names
def start_names(robot: Robot, send) -> None:
    """Round 0 of phase 1: each feature with a border link takes the two smallest pieces they
    reach and sends them over its set-joining rows; every other feature holds none."""
    st: HistoryState = robot.history
    st.conn = (robot.link_alive & (st.row_id >= 0)) | st.row_hist
    st.label = np.full(robot.m, NONE, np.int64)
    st.second = np.full(robot.m, NONE, np.int64)
    st.flag = np.zeros(robot.m, bool)
    changed = np.zeros(robot.m, bool)
    br = np.asarray(st.inp.border_r, np.int64)
    for r, p in zip(br.tolist(), np.asarray(st.inp.border_piece, np.int64).tolist(),
                    strict=True):
        changed[r] |= _offer(st, r, p)
    changed |= _flag_twice(st)
    _send_names(robot, changed, send)


def names_step(robot: Robot, inbox: list[Message], send, round_: int) -> None:
    """A round of phase 1: keep the two smallest pieces heard and the flag; send on the
    features that changed."""
    st: HistoryState = robot.history
    changed = np.zeros(robot.m, bool)
    for msg in inbox:
        if msg.kind != HLAB:
            continue
        s = msg.payload["s"].astype(np.int64).tolist()
        p = msg.payload["p"].astype(np.int64)
        p[p < 0] = NONE
        pairs = np.c_[p, msg.payload["flag"].astype(np.int64)].tolist()
        for f, (p1, p2, fl) in zip(s, pairs, strict=True):
            c = _offer(st, f, p1)
            c |= _offer(st, f, p2)
            if fl and not st.flag[f]:
                st.flag[f] = c = True
            changed[f] |= c
    changed |= _flag_twice(st)
    if changed.any():
        _send_names(robot, changed, send)


def _offer(st: HistoryState, f: int, q: int) -> bool:
    """Offer piece ``q`` (or :data:`NONE`) to own feature ``f``: it keeps its two smallest
    distinct pieces. Returns whether they changed."""
    lab = int(st.label[f])
    if q == NONE or q == lab:
        return False
    if q < lab:
        st.second[f], st.label[f] = lab, q
        return True
    if q < st.second[f]:
        st.second[f] = q
        return True
    return False


def _flag_twice(st: HistoryState) -> np.ndarray:
    """Flag the features of a set this robot holds two of (a piece belongs to one set, so two
    features naming one piece are in one set for good). Returns (m,) the newly flagged."""
    named = st.label != NONE
    labs, counts = np.unique(st.label[named], return_counts=True)
    twice = named & np.isin(st.label, labs[counts >= 2]) & ~st.flag
    st.flag |= twice
    return twice


def _send_names(robot: Robot, which: np.ndarray, send) -> None:
    st: HistoryState = robot.history
    rows = np.flatnonzero(st.conn & which[robot.link_r])
    for j in np.unique(robot.link_nbr[rows]).tolist():
        k = rows[robot.link_nbr[rows] == j]
        r = robot.link_r[k]
        p = np.stack([st.label[r], st.second[r]], axis=1)
        named = p != NONE
        # piece names as int32 while they fit (-1: none), else int64
        wide = bool(named.any()) and int(p[named].max()) >= np.iinfo(np.int32).max
        send(j, HLAB, {"s": robot.link_s[k].astype(np.int32),
                       "p": np.where(named, p, -1).astype(np.int64 if wide else np.int32),
                       "flag": st.flag[r].astype(np.uint8)})


def finish_names(robot: Robot) -> int:
    """After phase 1: the sets to examine (two pieces or more, or flagged: ``checked``), the
    flagged ones, and the sets this robot is the root of (it holds the head of the chain of
    the set's first piece). Returns the wave bits ``MANY`` and ``BAD``."""
    st: HistoryState = robot.history
    named = np.flatnonzero(st.label != NONE)
    st.flagged = {int(st.label[f]) for f in named.tolist() if st.flag[f]}
    st.checked = {int(st.label[f]) for f in named.tolist()
                  if st.flag[f] or st.second[f] != NONE}
    br = np.asarray(st.inp.border_r, np.int64)
    bp = np.asarray(st.inp.border_piece, np.int64)
    head = np.asarray(st.inp.border_head, bool) & (bp == st.label[br])
    st.roots = {int(p) for p in bp[head].tolist() if int(p) in st.checked}
    many = bool((st.second[named] != NONE).any())
    return (MANY if many else 0) | (BAD if st.flagged else 0)


# ----------------------------------------------------- phases 2-3: a tree per examined set
def _set_nbrs(robot: Robot) -> dict:
    """Set -> the robots this one shares a set-joining row of it with."""
    st: HistoryState = robot.history
    rows = np.flatnonzero(st.conn & (st.label[robot.link_r] != NONE))
    out: dict = {}
    for lab, j in zip(st.label[robot.link_r[rows]].tolist(), robot.link_nbr[rows].tolist(),
                      strict=True):
        out.setdefault(lab, set()).add(j)
    return out


def start_echo(robot: Robot, send) -> None:
    """Round 0 of phase 2: the root of each examined set sends a token to its neighbours of
    the set (Segall's echo: a robot takes the sender of its first token as its parent, sends
    tokens on, and answers its parent once every other neighbour answered — by its echo as a
    child, or by a token of its own)."""
    st: HistoryState = robot.history
    st.nbrs = _set_nbrs(robot)
    st.parent, st.children, st.waiting, st.collected, st.done = {}, {}, {}, {}, set()
    st.bad = set()
    _ask_each(send, HTOK, st.roots, st.nbrs, st.waiting)
    _complete(robot, send)


def echo_step(robot: Robot, inbox: list[Message], send, round_: int) -> None:
    """A round of phase 2: tokens and echoes (module docstring)."""
    st: HistoryState = robot.history
    first: dict = {}
    for msg in inbox:
        if msg.kind == HTOK:
            for lab in msg.payload["set"].tolist():
                first.setdefault(lab, []).append(msg.src)
        elif msg.kind == HECHO:
            for lab in msg.payload["set"].tolist():
                st.children.setdefault(lab, set()).add(msg.src)
                st.waiting.get(lab, set()).discard(msg.src)
            for lab, it in zip(msg.payload["lab"].tolist(), msg.payload["item"].tolist(),
                               strict=True):
                st.collected.setdefault(lab, set()).add(tuple(it))
    tokens: dict = {}
    for lab, senders in sorted(first.items()):
        if lab in st.waiting or lab in st.done:   # a token answers this robot's own
            for j in senders:
                st.waiting.get(lab, set()).discard(j)
            continue
        st.parent[lab] = min(senders)
        rest = set(st.nbrs.get(lab, ())) - {st.parent[lab]}
        st.waiting[lab] = rest - set(senders)
        for j in rest:
            tokens.setdefault(j, []).append(lab)
    _send_sets(send, HTOK, tokens)
    _complete(robot, send)


def _complete(robot: Robot, send) -> None:
    """Sets whose neighbours all answered: a robot echoes its own entries and those of its
    subtree to its parent; the root decides."""
    st: HistoryState = robot.history
    echoes: dict = {}
    ready = sorted(k for k, w in st.waiting.items() if not w and k not in st.done)
    own = own_entries(robot) if ready else {}
    for lab in ready:
        st.done.add(lab)
        items = st.collected.pop(lab, set()) | own.get(lab, set())
        if lab in st.roots:
            st.entries[lab] = sorted(items)
            if lab in st.flagged or _overlap(st.entries[lab]):
                st.bad.add(lab)
        else:
            echoes.setdefault(st.parent[lab], []).append((lab, sorted(items)))
    _send_items(send, HECHO, echoes, 4)


def _send_items(send, kind: str, by_robot: dict, width: int) -> None:
    """Per robot, one message answering its sets: ``by_robot`` robot -> [(set, items)]."""
    for j, sets in sorted(by_robot.items()):
        pairs = [(lab, it) for lab, its in sets for it in its]
        send(j, kind, {"set": np.array([lab for lab, _ in sets], np.int64),
                       "lab": np.array([p[0] for p in pairs], np.int64),
                       "item": np.array([p[1] for p in pairs], np.int64).reshape(-1, width)})


def _send_sets(send, kind: str, by_robot: dict) -> None:
    for j, labs in sorted(by_robot.items()):
        send(j, kind, {"set": np.array(sorted(labs), np.int64)})


def _ask_each(send, kind: str, labels, robots_of: dict, waiting: dict) -> None:
    """For each set of ``labels``, send ``kind`` to its robots in ``robots_of`` (one message
    per robot, all its sets) and wait for each of them (``waiting[set]``, in place)."""
    by_robot: dict = {}
    for lab in sorted(labels):
        waiting[lab] = set(robots_of.get(lab, ()))
        for j in waiting[lab]:
            by_robot.setdefault(j, []).append(lab)
    _send_sets(send, kind, by_robot)


def _overlap(entries) -> bool:
    """Whether one team robot has overlapping step runs among ``entries`` ``(piece, robot,
    lo, hi)`` (one retired frame in two pieces: runs of one piece never overlap), by the
    record's own test (:func:`overlapping_runs`)."""
    if not entries:
        return False
    _, rb, lo, hi = np.asarray(entries, np.int64).T
    return bool(overlapping_runs(np.zeros(len(rb), np.int64), rb, lo, hi))


def own_entries(robot: Robot) -> dict:
    """The retired entries of the pieces this robot's border links reach, per set with two
    pieces or more: ``(piece, robot, lo, hi)``."""
    st: HistoryState = robot.history
    inp = st.inp
    own: dict = {}
    piece_set = {}
    for r, p in zip(np.asarray(inp.border_r, np.int64).tolist(),
                    np.asarray(inp.border_piece, np.int64).tolist(), strict=True):
        if st.second[r] != NONE:
            piece_set[p] = int(st.label[r])
    for p, rb, lo, hi in zip(*(np.asarray(getattr(inp, k), np.int64).tolist() for k in
                               ("entry_piece", "entry_robot", "entry_lo", "entry_hi")),
                             strict=True):
        if p in piece_set:
            own.setdefault(piece_set[p], set()).add((p, rb, lo, hi))
    return own


def finish_echo(robot: Robot) -> int:
    """After phase 2: ``BAD`` if this robot is the root of a bad set."""
    return BAD if robot.history.bad else 0


def start_repair(robot: Robot, send) -> None:
    """Round 0 of phase 3: the root of each bad set asks its children down the tree for the
    set's open links."""
    st: HistoryState = robot.history
    st.pending, st.halves = {}, {}
    _ask_each(send, HGO, st.bad, st.children, st.pending)
    _up(robot, send)


def repair_step(robot: Robot, inbox: list[Message], send, round_: int) -> None:
    """A round of phase 3: the request goes down the tree, the halves come up (a robot sends
    its own and its subtree's once every child sent), the root solves :func:`rebuild` and
    the links it skips go down; each robot cuts its side."""
    st: HistoryState = robot.history
    go: dict = {}
    cuts: dict = {}
    for msg in inbox:
        if msg.kind == HGO:
            for lab in msg.payload["set"].tolist():
                st.pending[lab] = set(st.children.get(lab, ()))
                for j in st.pending[lab]:
                    go.setdefault(j, []).append(lab)
        elif msg.kind == HUP:
            for lab in msg.payload["set"].tolist():
                st.pending.get(lab, set()).discard(msg.src)
            for lab, it in zip(msg.payload["lab"].tolist(), msg.payload["item"].tolist(),
                               strict=True):
                st.halves.setdefault(lab, set()).add(tuple(it))
        elif msg.kind == HCUT:
            for lab, i in zip(msg.payload["lab"].tolist(), msg.payload["id"].tolist(),
                              strict=True):
                cuts.setdefault(lab, []).append(i)
    _send_sets(send, HGO, go)
    for lab, ids in sorted(cuts.items()):
        _cut_down(robot, send, lab, ids)
    _up(robot, send)


def _up(robot: Robot, send) -> None:
    st: HistoryState = robot.history
    ups: dict = {}
    ready = sorted(k for k, w in st.pending.items() if not w)
    own = own_links(robot, set(ready)) if ready else {}
    for lab in ready:
        del st.pending[lab]
        items = st.halves.pop(lab, set()) | own.get(lab, set())
        if lab in st.roots:
            skipped = rebuild_halves(sorted(items), st.entries.get(lab, []))
            _cut_down(robot, send, lab, skipped.tolist())
        else:
            ups.setdefault(st.parent[lab], []).append((lab, sorted(items)))
    _send_items(send, HUP, ups, 6)


def _cut_down(robot: Robot, send, lab: int, ids: list) -> None:
    """Cut this robot's side of ``ids`` (its rows and border links) and send them on to its
    children of the set."""
    st: HistoryState = robot.history
    if not ids:
        return
    mine = set(st.row_id[robot.link_alive & (st.row_id >= 0)].tolist()) \
        | set(np.asarray(st.inp.border_id, np.int64).tolist())
    st.cut.extend(i for i in ids if i in mine)
    for j in sorted(st.children.get(lab, ())):
        send(j, HCUT, {"lab": np.full(len(ids), lab, np.int64),
                       "id": np.asarray(ids, np.int64)})


def own_links(robot: Robot, want: set) -> dict:
    """The halves this robot sends up for each set of ``want``: one per kept real row and one
    per border link of its features, ``(link, feature, robot, step, quality bits, piece or
    -1)``."""
    st: HistoryState = robot.history
    inp = st.inp
    own: dict = {}
    gid = inp.gid0 + np.arange(robot.m, dtype=np.int64)
    qbits = st.row_quality.astype(np.float64).view(np.int64)
    for k in np.flatnonzero(robot.link_alive & (st.row_id >= 0)).tolist():
        lab = int(st.label[robot.link_r[k]])
        if lab in want:
            own.setdefault(lab, set()).add((int(st.row_id[k]), int(gid[robot.link_r[k]]),
                                            inp.robot, inp.step, int(qbits[k]), -1))
    bq = np.asarray(inp.border_quality, np.float64).view(np.int64)
    for r, p, i, q in zip(np.asarray(inp.border_r, np.int64).tolist(),
                          np.asarray(inp.border_piece, np.int64).tolist(),
                          np.asarray(inp.border_id, np.int64).tolist(), bq.tolist(),
                          strict=True):
        lab = int(st.label[r])
        if lab in want:
            own.setdefault(lab, set()).add((i, int(gid[r]), inp.robot, inp.step, q, p))
    return own


def rebuild_halves(halves, entries) -> np.ndarray:
    """:func:`rebuild` on flooded items: ``halves`` ``(link, feature, robot, step, quality
    bits, piece)`` (a real link's two halves, or a border link's one with its piece), entries
    ``(piece, robot, lo, hi)``. A real link of which one half arrived is skipped (both its ends
    are in the set, so both robots send theirs: only a lost message leaves one)."""
    groups: dict = {}
    real: dict = {}
    border: dict = {}
    quality: dict = {}
    for i, g, rb, s, qb, p in halves:
        groups[g] = {rb: [(s, s)]}
        quality[i] = float(np.int64(qb).view(np.float64))
        if p >= 0:
            border[i] = (g, -1 - p)
            groups.setdefault(-1 - p, {})
        else:
            real.setdefault(i, []).append(g)
    for p, rb, lo, hi in entries:
        groups.setdefault(-1 - p, {}).setdefault(rb, []).append((lo, hi))
    half = sorted(i for i, ends in real.items() if len(ends) != 2)
    ends = sorted([(i, e[0], e[1]) for i, e in real.items() if len(e) == 2]
                  + [(i, g, node) for i, (g, node) in border.items()])
    e = np.asarray(ends, np.int64).reshape(-1, 3)
    out = rebuild(groups, e[:, 0], e[:, 1], e[:, 2],
                  np.asarray([quality[i] for i in e[:, 0].tolist()], np.float64))
    return np.union1d(out, np.asarray(half, np.int64)).astype(np.int64)


def rebuild(groups: dict, ids: np.ndarray, a: np.ndarray, b: np.ndarray,
            quality: np.ndarray) -> np.ndarray:
    """The history repair of one bad set (step 3, :mod:`.engines.online_history`): the link ids it
    skips.

    ``groups``: node -> ``{team robot: [(lo, hi), ...]}`` the step runs of the frames a node
    holds (a window feature: its frame's step; a retired piece, node ``-1 - piece``: its
    entries); ``ids``, ``a``, ``b``, ``quality``: the set's open links (kept window links and
    border links) between nodes. Starting from every node alone (a retired piece whole: its
    links are final), the links are added by decreasing quality, ties by id — the order of
    the evidence rule's Kruskal merge — and a link is skipped when the two groups it would
    join hold overlapping runs of one robot (one frame twice). Deterministic: every robot of
    the set computes the same.

    >>> rebuild({1: {0: [(5, 5)]}, 2: {1: [(5, 5)]}, 3: {0: [(5, 5)]}},
    ...         np.array([10, 11]), np.array([1, 2]), np.array([2, 3]), np.array([0.9, 0.5]))
    array([11])
    """
    groups = {x: {r: list(v) for r, v in runs.items()} for x, runs in groups.items()}
    parent = {x: x for x in groups}
    for x in np.concatenate([a, b]).tolist():
        groups.setdefault(x, {})
        parent.setdefault(x, x)

    def find(x):
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    skipped = []
    for k in np.lexsort((ids, -quality)).tolist():
        rx, ry = find(int(a[k])), find(int(b[k]))
        if rx == ry:
            continue
        x, y = groups[rx], groups[ry]
        if any(lo <= h and l2 <= hi for r in x.keys() & y.keys()
               for lo, hi in x[r] for l2, h in y[r]):
            skipped.append(int(ids[k]))
            continue
        if len(x) < len(y):
            rx, ry, x, y = ry, rx, y, x
        parent[ry] = rx
        for r, runs in y.items():
            x.setdefault(r, []).extend(runs)
    return np.asarray(skipped, np.int64)


def runs_by_robot(group, robot, lo, hi):
    """Step runs sorted by (group, robot, lo): the sorted arrays, ``head`` (the first run of
    each (group, robot)), ``gid`` (its index) and ``run_max`` (the largest ``hi`` so far
    within it)."""
    order = np.lexsort((lo, robot, group))
    g, r, lo, hi = group[order], robot[order], lo[order], hi[order]
    head = np.r_[True, (g[1:] != g[:-1]) | (r[1:] != r[:-1])]
    gid = np.cumsum(head) - 1
    big = int(hi.max()) + 2
    run_max = np.maximum.accumulate(gid * big + hi) - gid * big
    return g, r, lo, hi, head, gid, run_max


def overlapping_runs(group, robot, lo, hi) -> list[int]:
    """Groups in which one robot has two overlapping step runs (one frame twice).

    >>> overlapping_runs(np.array([0, 0, 1, 1]), np.array([2, 2, 2, 3]),
    ...                  np.array([0, 4, 0, 0]), np.array([3, 5, 9, 9]))
    []
    >>> overlapping_runs(np.array([0, 0]), np.array([2, 2]), np.array([0, 3]), np.array([3, 5]))
    [0]
    """
    if not len(group):
        return []
    g, _, lo, _, head, _, run_max = runs_by_robot(group, robot, lo, hi)
    hit = ~head & (lo <= np.r_[-1, run_max[:-1]])
    return np.unique(g[hit]).tolist()


#: the check's phases in order, as both drivers run them (the simulator's
#: :func:`.engines.history_run.run_history`, a robot alone's :func:`.alone.run_history_locally`):
#: ``(name, start, step, finish)``; ``finish(robot)`` (idempotent) settles the robot's state
#: after the phase and returns the wave bits that decide the next (None: the last phase)
PHASES = (("names", start_names, names_step, finish_names),
          ("echo", start_echo, echo_step, finish_echo),
          ("repair", start_repair, repair_step, None))
