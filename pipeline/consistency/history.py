"""The history check of an online step run by the robots (step 3 of :mod:`.engines.online`).

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
   with the two smallest pieces its border links reach, every other feature with none, and
   the two smallest pieces heard flood over those links (label flooding, as :mod:`.labels`,
   from those features only: a set without a piece sends nothing). At the end every feature
   of such a set holds its two smallest pieces: the first names the set at every robot
   alike, the second says whether it has two or more. A robot holding two features of one
   set flags it (its frame twice: a conflict a robot sees alone). Bits: ``MANY``, ``BAD``.
2. **Entries** (``hset``, items ``(piece, robot, lo, hi)``; sets with two pieces or more,
   and flagged sets). The robots flood the retired entries of their set's pieces, and the
   item ``(-1, -1, -1, -1)`` for a set they flagged; a set in which one team robot has
   overlapping runs (one retired frame in two pieces) is *bad*, as is a flagged set.
3. **Repair** (``hset``, items ``(link, feature, robot, step, quality, piece)``; bad sets).
   The robots flood the set's open links: each robot one *half* per kept real link of its
   features (its end: the feature's global id, team robot and step) and one per border link
   (with its piece; quality as the bits of its float64). Every robot of the set then holds
   the same links and entries and computes :func:`rebuild` on them — the same deterministic
   function the record computes — and cuts its side of the links it skips: its rows and its
   border links (:attr:`HistoryState.cut`; the step's record applies them, reason
   ``history``).

Same decisions as the record's check (:meth:`.engines.online.OnlineAssociation.
_history_check` with ``overturn``, the default): the sets are the same components, a set is
bad under the same two conditions (runs of one robot in one piece never overlap, so overlap
needs two pieces; a window frame's single step never overlaps a retired run, so a set with
one piece needs no entries to be repaired), and :func:`rebuild` gets the same groups and
links in the same order. Property-tested against the record's check
(``tests/pipeline/consistency/test_history.py``).

Costs: counted by the transport as every message (a flood item crosses each robot pair of
its set that shares a link, once per direction at most): 20 bytes per feature and change in
phase 1, 8 bytes per set name plus 8 per item column in phases 2–3.

Payloads: ``hlab`` ``s`` (K,) int32 (the receiver's feature), ``p`` (K, 2) int64 (its two
smallest pieces heard, :data:`NONE` where fewer); ``hset`` ``lab`` (K,) int64, ``item``
(K, c) int64.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pipeline.consistency.robot import Robot
from pipeline.transport import Message

__all__ = ["HistoryInputs", "HistoryState", "equip_history", "rebuild", "rebuild_halves",
           "start_names", "names_step", "finish_names", "start_flood", "flood_step",
           "own_entries", "finish_entries", "own_links", "finish_repair", "HLAB", "HSET",
           "MANY", "BAD", "NONE"]

HLAB, HSET = "hlab", "hset"
#: wave bits of phase 1 (beside the reliable channel's ``LOST``): a set with two pieces or
#: more, a set flagged (phase 2 runs); of phase 2: a bad set (phase 3 runs)
MANY, BAD = 8, 16
#: phase 2's item that flags a set holding one window frame twice
_FLAG = (-1, -1, -1, -1)
#: no piece (phase 1): a feature no piece reached; its set cannot be bad, it takes no part
NONE = np.iinfo(np.int64).max


@dataclass
class HistoryInputs:
    """What one window frame's robot holds for the check (module docstring).

    ``gid0``: the online global id of the frame's feature 0; ``robot``, ``step``: the team
    robot that took the frame and its step. Rows (any order; matched to the robot's link
    table by ``(row_nbr, row_s)``): ``row_id`` the link's id (-1: a history link),
    ``row_quality``, ``row_hist`` (a history link joins the row's two features). Border links:
    ``border_r`` (own feature), ``border_piece``, ``border_id``, ``border_quality``. Entries
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
    entry_piece: np.ndarray
    entry_robot: np.ndarray
    entry_lo: np.ndarray
    entry_hi: np.ndarray

    ARRAYS = ("row_nbr", "row_s", "row_id", "row_quality", "row_hist", "border_r",
              "border_piece", "border_id", "border_quality", "entry_piece", "entry_robot",
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
    """A robot's state of the check: ``label`` (m,) its features' set names (phase 1),
    ``conn`` the rows that join sets (kept real rows, history rows), ``row_id``,
    ``row_quality``, ``row_hist`` per row of its link table, ``label`` / ``second`` (m,)
    its features' two smallest pieces heard (phase 1; ``label`` names the set), ``items``
    set -> the flooded items of the current phase, ``flagged`` / ``bad`` / ``entries`` what
    phases 1–2 learnt, ``cut`` the link ids this robot cut (its rows and border links)."""

    inp: HistoryInputs
    row_id: np.ndarray
    row_quality: np.ndarray
    row_hist: np.ndarray
    conn: np.ndarray = None
    label: np.ndarray = None
    second: np.ndarray = None
    items: dict = field(default_factory=dict)
    fresh: dict = field(default_factory=dict)
    flagged: set = field(default_factory=set)
    bad: set = field(default_factory=set)
    entries: dict = field(default_factory=dict)
    cut: list = field(default_factory=list)

    def nbytes(self) -> int:
        held = sum(len(it) for v in self.items.values() for it in v)
        return int(sum(a.nbytes for a in (self.row_id, self.row_quality, self.row_hist))
                   + 8 * held + (0 if self.label is None else 2 * self.label.nbytes))


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
    br = np.asarray(st.inp.border_r, np.int64)
    bp = np.asarray(st.inp.border_piece, np.int64)
    changed = _offer(st, br, bp)
    _send_names(robot, changed, send)


def names_step(robot: Robot, inbox: list[Message], send, round_: int) -> None:
    """A round of phase 1: keep the two smallest pieces heard; send on the features they
    changed."""
    st: HistoryState = robot.history
    changed = np.zeros(robot.m, bool)
    for msg in inbox:
        if msg.kind != HLAB:
            continue
        s, p = msg.payload["s"].astype(np.int64), msg.payload["p"]
        changed |= _offer(st, np.r_[s, s], np.r_[p[:, 0], p[:, 1]])
    if changed.any():
        _send_names(robot, changed, send)


def _offer(st: HistoryState, r: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Offer pieces ``p`` to own features ``r``: each keeps its two smallest distinct ones.
    Returns (m,) bool, the features whose pair changed."""
    changed = np.zeros(len(st.label), bool)
    keep = (p != NONE) & (p < st.second[r]) & (p != st.label[r])
    for f, q in zip(r[keep].tolist(), p[keep].tolist(), strict=True):
        lab, sec = int(st.label[f]), int(st.second[f])
        if q == lab or q >= sec:
            continue
        if q < lab:
            st.label[f], st.second[f] = q, lab
        else:
            st.second[f] = q
        changed[f] = True
    return changed


def _send_names(robot: Robot, which: np.ndarray, send) -> None:
    st: HistoryState = robot.history
    rows = np.flatnonzero(st.conn & which[robot.link_r])
    for j in np.unique(robot.link_nbr[rows]).tolist():
        k = rows[robot.link_nbr[rows] == j]
        r = robot.link_r[k]
        send(j, HLAB, {"s": robot.link_s[k].astype(np.int32),
                       "p": np.stack([st.label[r], st.second[r]], axis=1).astype(np.int64)})


def finish_names(robot: Robot) -> int:
    """After phase 1: the sets this robot holds two features of are flagged; returns the
    wave bits ``MANY`` (a set of its features has two pieces or more) and ``BAD`` (it
    flagged a set)."""
    st: HistoryState = robot.history
    named = st.label != NONE
    labs, counts = np.unique(st.label[named], return_counts=True)
    st.flagged = set(labs[counts >= 2].tolist())
    return (MANY if (st.second[named] != NONE).any() else 0) | (BAD if st.flagged else 0)


# ------------------------------------------------------------ phases 2-3: floods per set
def _set_nbrs(robot: Robot) -> dict:
    """Set -> the robots this one shares a set-joining row of it with."""
    st: HistoryState = robot.history
    rows = np.flatnonzero(st.conn & (st.label[robot.link_r] != NONE))
    out: dict = {}
    for lab, j in zip(st.label[robot.link_r[rows]].tolist(), robot.link_nbr[rows].tolist(),
                      strict=True):
        out.setdefault(lab, set()).add(j)
    return out


def start_flood(robot: Robot, send, own: dict) -> None:
    """Round 0 of a flood: ``own`` set -> the robot's own items (tuples of ints) of it; the
    robot sends them to its neighbours of each set."""
    st: HistoryState = robot.history
    st.items = {lab: set(v) for lab, v in own.items()}
    st.fresh = {lab: set(v) for lab, v in own.items() if v}
    _send_fresh(robot, send)


def flood_step(robot: Robot, inbox: list[Message], send, round_: int) -> None:
    """A round of a flood: keep the items not held yet; send them on."""
    st: HistoryState = robot.history
    for msg in inbox:
        if msg.kind != HSET:
            continue
        labs, items = msg.payload["lab"].tolist(), msg.payload["item"].tolist()
        for lab, it in zip(labs, items, strict=True):
            it = tuple(it)
            have = st.items.setdefault(lab, set())
            if it not in have:
                have.add(it)
                st.fresh.setdefault(lab, set()).add(it)
    _send_fresh(robot, send)


def _send_fresh(robot: Robot, send) -> None:
    st: HistoryState = robot.history
    if not st.fresh:
        return
    nbrs = _set_nbrs(robot)
    out: dict = {}
    for lab, its in st.fresh.items():
        for j in nbrs.get(lab, ()):
            out.setdefault(j, []).extend((lab, it) for it in sorted(its))
    st.fresh = {}
    for j, pairs in sorted(out.items()):
        send(j, HSET, {"lab": np.array([p[0] for p in pairs], np.int64),
                       "item": np.array([p[1] for p in pairs], np.int64)})


def own_entries(robot: Robot) -> dict:
    """Phase 2's own items: the entries of the pieces of each set with two pieces or more
    that this robot's border links reach, and :data:`_FLAG` for each set it flagged."""
    st: HistoryState = robot.history
    inp = st.inp
    own: dict = {lab: {_FLAG} for lab in st.flagged}
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


def finish_entries(robot: Robot, ran: bool = True) -> int:
    """After phase 2 (``ran``: it ran; a robot alone skips it when no set has two pieces and
    none is flagged): the flagged sets and those in which one team robot has overlapping
    runs are bad; returns ``BAD`` if this robot holds a feature of one."""
    st: HistoryState = robot.history
    items = st.items if ran else {}
    st.entries = {lab: sorted(it for it in its if it != _FLAG) for lab, its in items.items()}
    st.bad = set(st.flagged) | {lab for lab, its in items.items() if _FLAG in its}
    for lab, ent in st.entries.items():
        runs = sorted((rb, lo, hi) for _, rb, lo, hi in ent)
        last_rb, reach = None, None
        for rb, lo, hi in runs:   # by robot, then start: a start within the reach overlaps
            if rb == last_rb and lo <= reach:
                st.bad.add(lab)
                break
            reach = hi if rb != last_rb else max(reach, hi)
            last_rb = rb
    return BAD if st.bad else 0


def own_links(robot: Robot) -> dict:
    """Phase 4's own items: per bad set, one half per kept real row and one per border link
    of the robot's features: ``(link, feature, robot, step, quality bits, piece or -1)``."""
    st: HistoryState = robot.history
    inp = st.inp
    own: dict = {}
    gid = inp.gid0 + np.arange(robot.m, dtype=np.int64)
    qbits = st.row_quality.astype(np.float64).view(np.int64)
    for k in np.flatnonzero(robot.link_alive & (st.row_id >= 0)).tolist():
        lab = int(st.label[robot.link_r[k]])
        if lab in st.bad:
            own.setdefault(lab, set()).add((int(st.row_id[k]), int(gid[robot.link_r[k]]),
                                            inp.robot, inp.step, int(qbits[k]), -1))
    bq = np.asarray(inp.border_quality, np.float64).view(np.int64)
    for r, p, i, q in zip(np.asarray(inp.border_r, np.int64).tolist(),
                          np.asarray(inp.border_piece, np.int64).tolist(),
                          np.asarray(inp.border_id, np.int64).tolist(), bq.tolist(),
                          strict=True):
        lab = int(st.label[r])
        if lab in st.bad:
            own.setdefault(lab, set()).add((i, int(gid[r]), inp.robot, inp.step, q, p))
    return own


def finish_repair(robot: Robot) -> None:
    """After phase 4: every robot of a bad set solves :func:`rebuild` on the set's flooded
    links and entries and cuts its side of the links it skips (:attr:`HistoryState.cut`)."""
    st: HistoryState = robot.history
    mine_rows = {int(i) for i in st.row_id[robot.link_alive & (st.row_id >= 0)].tolist()}
    mine = mine_rows | {int(i) for i in np.asarray(st.inp.border_id, np.int64).tolist()}
    for lab in sorted(st.bad):
        halves = sorted(st.items.get(lab, ()))
        ent = st.entries.get(lab, [])
        skipped = rebuild_halves(halves, ent)
        st.cut.extend(i for i in skipped.tolist() if i in mine)


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
    """The history repair of one bad set (step 3 of :mod:`.engines.online`): the link ids it
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
