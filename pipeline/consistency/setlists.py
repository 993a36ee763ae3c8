"""Detection by bounded label flooding: each feature learns its set's member list, or that the
set is *large* (more than ``B`` features), with memory that follows the links.

The evidence rule (:mod:`.evidence`) needs, for each conflictive set ``C``, the list of its
features at every robot of ``C`` (a robot solves ``C`` once it holds a bundle for each); the
detection of Sec. III (Aragüés et al., eq. 5) provides it as the row ``X_i·(t)`` of every
feature: memory and messages in ``Σ |C|²``, whatever the set's size. Here every active feature
floods instead the ``B + 1`` smallest global feature ids it has heard of (``B`` the *bundle
budget*, :func:`bundle_budget`), merged by "the ``B + 1`` smallest of the union" — an
order-insensitive, idempotent operation, as the ``min`` of :mod:`.labels` (which is the case
``B = 0``). At the end of the phase (nothing in flight):

* a feature that holds ``B + 1`` ids knows its set is *large* (``|C| > B``);
* any other feature holds the whole member list of its set (``|C| ≤ B``), which is its row
  of ``X`` in Sec. III (:func:`.detection.find_conflictive_sets`): it is *conflictive*
  (rules 8–9) iff two of the ids are of one camera (cameras from the public offsets), its
  set is named by the smallest id (``set_label``), and a non-conflictive feature's track is
  named by that id (``track_label``), exactly as the first detection of today's evidence rule
  names them.

Why the outcome is exact (the operation is that of :mod:`.labels`, generalized)
    Let ``C`` be a connected set of active features over alive links and ``S = min_{B+1}(C)``
    its ``B + 1`` smallest ids. A feature's list only ever holds ids of ``C`` (ids travel
    along the set's links) and only loses an id for a smaller one, so an id of ``S`` — fewer
    than ``B + 1`` ids are smaller — is never evicted once heard; every id of ``S`` starts at
    its feature and is forwarded along every link the round after it enters a list, so it
    reaches every feature of ``C``. At the end every feature holds ``S``: all features of
    ``C`` agree on *large*, and a small set's features on its whole list.

Delta messages
    A feature sends only the ids that entered its list in the last step (round 0: its own
    id) to every robot it is linked to. The receiver merges them into its list; since every
    id of a list was sent when it entered, what a robot has received over a link is always a
    superset of the sender's current list, so the deltas give the same lists as whole lists
    would.

Bounds and cost
    ``diam(C) + 1`` rounds, as :mod:`.labels` (an id moves one link per round). Memory per
    robot: its links plus ``≤ B + 1`` ids per active feature, ``O(L_i + m_i B)``, never
    ``Σ |C|²``. Messages: one per linked neighbour and round in which a feature linked to it
    learnt new ids; payload ``feat`` (F,) int32 (the sender's local ids), ``deg`` (F,) int32
    (new ids of each), ``ids`` (D,) id (:func:`.sync.id_dtype`'s rule: int32 below ``2**31``
    features). Over the phase a link carries at most the ids that ever entered its ends'
    lists.

The rule that uses it: :mod:`.engines.evidence_stage` (small sets solved by the evidence
rule's bundles, large sets by the ``sync`` merge restricted to their links).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from pipeline.consistency.detection import reset_detection
from pipeline.consistency.keys import isin_sorted, ranges
from pipeline.consistency.robot import Robot
from pipeline.consistency.sync import id_dtype
from pipeline.transport import Message

__all__ = ["SetListState", "start_setlists", "setlists_step", "finish_setlists", "KIND",
           "SET_BUNDLE_BYTES", "bundle_bytes_bound", "bundle_budget", "merge_smallest"]

KIND = "setlist"
#: the bytes a robot may hold for the bundles of one conflictive set (the default bundle
#: budget ``B`` is the largest set whose bundles fit, :func:`bundle_budget`). 256 KiB: on a
#: 101-camera team B = 152 (CMU hotel's true landmarks, 101 features, are small sets), on
#: the rendered formations (≤ 16 cameras) B ≥ 700, far above their sets
SET_BUNDLE_BYTES = 1 << 18
_EMPTY = np.zeros(0, dtype=np.int64)


def bundle_bytes_bound(n: int) -> int:
    """Largest bytes a robot holds for one feature of a set (:func:`.evidence.bundle_nbytes`
    plus the member id): keypoint 8, id and camera 12, projection 96, member 8, and 16 per
    link (other end, weight), one link at most to each of the ``n - 1`` other cameras
    (Assumption 2.2): ``124 + 16 (n - 1)``."""
    return 124 + 16 * max(int(n) - 1, 0)


def bundle_budget(n: int, budget: int | None = None) -> int:
    """The bundle budget ``B`` of a team of ``n`` robots: ``budget`` if given (at least 1),
    else the largest set whose bundles fit :data:`SET_BUNDLE_BYTES` at a robot
    (:func:`bundle_bytes_bound`), at least 2. Every robot knows ``n``, so all compute the
    same ``B``."""
    if budget is not None:
        if int(budget) < 1:
            raise ValueError(f"bundle budget {budget!r}: a set size of at least 1 features")
        return int(budget)
    return max(2, SET_BUNDLE_BYTES // bundle_bytes_bound(n))


@dataclass
class SetListState:
    """A robot's flooded lists: entries ``(r, id)`` sorted by ``(r, id)``, at most ``B + 1``
    per own active feature ``r``.

    Attributes
    ----------
    budget : int — ``B``
    r, ids : (K,) int64 — the lists
    new_r, new_ids : (K',) int64 — entries that entered in the last step (to send)
    heard : (m,) bool — a linked active feature was heard of
    large : (m,) bool — set by :func:`finish_setlists`: the feature's set holds more than
        ``B`` features
    """

    budget: int
    r: np.ndarray
    ids: np.ndarray
    new_r: np.ndarray
    new_ids: np.ndarray
    heard: np.ndarray
    large: np.ndarray

    def nbytes(self) -> int:
        return sum(int(a.nbytes) for a in (self.r, self.ids, self.new_r, self.new_ids,
                                           self.heard, self.large))


def _measure(robot: Robot) -> None:
    robot.peak_memory_bytes = max(robot.peak_memory_bytes,
                                  robot.memory_bytes() + robot.setlists.nbytes())


def _send_new(robot: Robot, send) -> None:
    """The new entries of every feature to each robot it is linked to (alive links)."""
    st: SetListState = robot.setlists
    if st.new_r.size == 0:
        return
    cnt = np.bincount(st.new_r, minlength=robot.m)
    ptr = np.r_[0, np.cumsum(cnt)]
    sel = np.flatnonzero(robot.link_alive & robot.active[robot.link_r]
                         & (cnt[robot.link_r] > 0))
    new_ids = st.new_ids
    st.new_r, st.new_ids = _EMPTY, _EMPTY
    if sel.size == 0:
        return
    nbr = robot.link_nbr[sel]  # the link table is sorted by neighbour
    idt = id_dtype(robot.m_total)
    for part in np.split(sel, np.flatnonzero(np.diff(nbr)) + 1):
        r = np.unique(robot.link_r[part]).astype(np.int64)
        send(int(robot.link_nbr[part[0]]), KIND,
             {"feat": r.astype(np.int32), "deg": cnt[r].astype(np.int32),
              "ids": new_ids[ranges(ptr[r], ptr[r + 1])].astype(idt)})


def merge_smallest(old: np.ndarray, incoming: np.ndarray, base, keep: int):
    """The ``keep`` smallest keys of each group (``key // base``) of ``old ∪ incoming``, and
    those of them not in ``old``: ``(merged, fresh)``, both sorted; ``old`` sorted, unique.

    >>> merge_smallest(np.array([10, 12]), np.array([11, 12, 21]), 10, 2)
    (array([10, 11, 21]), array([11, 21]))
    """
    merged = np.sort(np.r_[old, incoming])
    if merged.size:  # sorting then dropping repeats beats hashing at these sizes
        merged = merged[np.r_[True, merged[1:] != merged[:-1]]]
    group = merged // base
    head = np.r_[0, np.flatnonzero(group[1:] != group[:-1]) + 1] if merged.size else _EMPTY
    rank = np.arange(merged.size) - np.repeat(head, np.diff(np.r_[head, merged.size]))
    merged = merged[rank < keep]
    return merged, merged[~isin_sorted(merged, old)]


def start_setlists(robot: Robot, iteration: int, send, budget: int) -> None:
    """Round 0: every active feature (Sec. IV after Cor. 4.4, as the rows of Sec. III choose
    them) starts with its own id and sends it along its alive links."""
    reset_detection(robot, iteration)
    rows = np.flatnonzero(robot.active).astype(np.int64)
    ids = robot.gid0 + rows
    robot.setlists = SetListState(budget=int(budget), r=rows, ids=ids, new_r=rows.copy(),
                                  new_ids=ids.copy(), heard=np.zeros(robot.m, dtype=bool),
                                  large=np.zeros(robot.m, dtype=bool))
    robot.X = sp.csr_matrix((robot.m, robot.m_total), dtype=bool)
    robot.X_new = robot.X
    robot.stopped = rows.size == 0
    _send_new(robot, send)
    _measure(robot)


def setlists_step(robot: Robot, inbox: list[Message], send, round_: int = 0) -> None:
    """One round: merge the ids heard over each alive link between two active features into
    the feature's list (the ``B + 1`` smallest of the union), send the ids that entered."""
    st: SetListState = robot.setlists
    got_r, got_id = [], []
    for msg in inbox:
        if msg.kind != KIND:
            continue
        p = msg.payload
        feat = np.asarray(p["feat"], dtype=np.int64)
        if feat.size == 0:
            continue
        deg = np.asarray(p["deg"], dtype=np.int64)
        link = robot.find_links(np.full(feat.size, msg.src), feat)
        ok = link >= 0
        ok[ok] = robot.link_alive[link[ok]] & robot.active[robot.link_r[link[ok]]]
        if not ok.any():
            continue
        start = np.r_[0, np.cumsum(deg)]
        k = np.flatnonzero(ok)
        got_r.append(np.repeat(robot.link_r[link[k]].astype(np.int64), deg[k]))
        got_id.append(np.asarray(p["ids"], dtype=np.int64)[ranges(start[k], start[k + 1])])
    if got_r:
        heard_r = np.concatenate(got_r)
        st.heard[heard_r] = True
        M = np.int64(robot.m_total)
        key, new = merge_smallest(st.r * M + st.ids, heard_r * M + np.concatenate(got_id), M,
                                  st.budget + 1)
        st.r, st.ids = key // M, key % M
        st.new_r, st.new_ids = new // M, new % M
    _send_new(robot, send)
    robot.t_stop = int(round_)
    _measure(robot)


def finish_setlists(robot: Robot) -> None:
    """The outcome: ``large``; on the small sets the outputs of
    :func:`.detection.find_conflictive_sets` (``conflictive``, ``set_label``, the rows of
    ``X`` of the conflictive features, ``track_label`` of the non-conflictive ones)."""
    st: SetListState = robot.setlists
    m = robot.m
    count = np.bincount(st.r, minlength=m)
    st.large = robot.active & (count > st.budget)
    first = np.full(m, -1, dtype=np.int64)
    ptr = np.r_[0, np.cumsum(count)]
    has = count > 0
    first[has] = st.ids[ptr[:-1][has]]
    # rules (8)-(9) on a small set's list: two ids of one camera
    cam = np.searchsorted(robot.offsets, st.ids, side="right") - 1
    key = np.sort(st.r * np.int64(robot.n) + cam)  # (feature, camera) of every id
    twice = key[1:][key[1:] == key[:-1]] // np.int64(robot.n)
    dup = np.zeros(m, dtype=bool)
    dup[twice] = True
    small = robot.active & ~st.large
    conflictive = small & dup
    robot.conflictive = conflictive
    robot.set_label = np.where(conflictive, first, -1)
    named = small & ~dup & st.heard
    robot.track_label[named] = first[named]
    rows = conflictive[st.r]
    robot.X = sp.csr_matrix((np.ones(int(rows.sum()), dtype=bool),
                             st.ids[rows].astype(np.int64),
                             np.r_[0, np.cumsum(np.where(conflictive, count, 0))]),
                            shape=(m, robot.m_total))
    robot.X_new = robot.X
    robot.stopped = True
    _measure(robot)
