"""Detection by label flooding: the outcome of Sec. III with memory that follows the links.

The detection of Aragüés et al. (Sec. III, eq. 5) makes every robot hold, for each of its
features, the whole row ``X_i·(t)``: every feature of its association set (memory and
messages in ``Σ |C|²``: a dense 101-frame input joins thousands of features into one set).
What Alg. 1 reads from a detection is much less: for each own feature, whether it is
*conflictive* (rules 8–9: its set holds two features of one camera), the set's *label* (its
smallest global feature id) and the set's *root* (eq. 10: the robot with the most features
in the set, ties to the lowest id), and for a feature found non-conflictive the name of its
track (the same smallest id). This module computes exactly these by flooding, per feature,
three values along the links, each combined by an order-insensitive, idempotent operation:

``label``
    the smallest global id heard of (``min``): starts at the feature's own id;
``dup``
    "some robot holds two features of this set" (``or``): a robot sets it on every own
    feature of a group of its features that share a label (two features that share a label
    are in one set: a label travels only along the set's links);
``key``
    the best root candidate heard of (``max``), ``count · (n + 1) + (n − robot)``: ``count``
    the number of the robot's own features that share the feature's label.

A robot re-derives its groups after every round (features with equal labels), merges their
``dup`` and ``key`` and sends each changed feature's triple to the robots it is linked to.

Why the outcome equals the rows of Sec. III (the phase ends when nothing is in flight)
    Let ``C`` be a connected set of active features over alive links (the graph eq. 5 runs
    on: both ends active, Sec. IV after Cor. 4.4). (i) *label*: the minimum of a set of ids
    flooded over a connected graph: at the end every feature of ``C`` holds ``min C``, which
    is the first column of its row of ``X`` (:func:`.detection.find_conflictive_sets`).
    (ii) *dup*: a feature's ``dup`` is true only if two features of one robot shared a label,
    hence a set, so it never lies; conversely when ``C`` holds two features of robot ``j``,
    both end with label ``min C``, ``j`` sets ``dup`` on them, and the ``or`` reaches all of
    ``C``: at the end ``dup`` is rule (8)/(9) exactly. (iii) *key*: a robot's count for any
    label it ever held is at most its number of features in ``C`` (features sharing a label
    are in ``C``), and at the end it counts exactly those; so the ``max`` over ``C`` is the
    largest true count with the lowest robot id among its ties: eq. (10). Every feature of a
    set ends with the same triple, so every robot names the set and its root alike.
    A feature that never hears of a linked active feature is alone (its row would be itself):
    it is not named as a track, as in :func:`.detection.find_conflictive_sets`.

Bounds and cost
    A value moves one link per round and changes only by improving, so every label is final
    within ``diam(C)`` rounds; a ``dup`` flag or a final count is known only once the labels
    of a robot's features meet, and then floods another ``diam(C)`` rounds: the phase ends
    within ``2 diam(C) + 1`` rounds after the start for every set (the rows of eq. 5 need
    ``d + 1``, Cor. 3.6; a path 0:0 - 1:0 - ... - 5:0 - 0:1 takes 10 rounds). Memory per robot: its links and four numbers per own feature
    (``O(L_i + m_i)``), never ``Σ |C|²``. Messages: one per linked neighbour and round in
    which some feature linked to it changed; payload per changed feature ``feat`` (int32,
    the sender's local id), ``label`` (id), ``dup`` (uint8), ``key`` (int64).

The phases: :func:`.engines.paper_labels.run_paper_labels` (the simulator: every robot on
its own inbox, phases ended when nothing is in flight) and
:func:`.alone.run_paper_labels_locally` (a robot in its own process over the reliable
channel, phases ended by the termination wave, with the closing round of the paper rule)
alternate this detection with Alg. 1 (:mod:`.resolution`) until a detection finds no
conflictive feature (Prop. 4.5) — the rule ``paper-labels`` of :mod:`.rules`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.consistency.detection import reset_detection
from pipeline.consistency.reliable import ReliableState, cut_lost
from pipeline.consistency.robot import Robot
from pipeline.transport import Message

__all__ = ["LabelState", "start_labels", "labels_step", "finish_labels",
           "start_labels_reliable", "labels_round", "labels_done", "KIND"]

KIND = "labels"


@dataclass
class LabelState:
    """A robot's flooded values, one entry per own feature (only active ones are used)."""

    label: np.ndarray  # (m,) int64 — smallest global id heard of
    dup: np.ndarray  # (m,) bool — a robot holds two features of the set
    key: np.ndarray  # (m,) int64 — best root candidate heard of
    heard: np.ndarray  # (m,) bool — a linked active feature was heard of
    changed: np.ndarray  # (m,) bool — to send in the next message

    def nbytes(self) -> int:
        return sum(int(a.nbytes) for a in (self.label, self.dup, self.key, self.heard,
                                           self.changed))


def _id_dtype(robot: Robot):
    return np.int32 if robot.m_total < 2**31 else np.int64


def _own_key(robot: Robot, count: np.ndarray) -> np.ndarray:
    n = int(robot.n)
    return count.astype(np.int64) * (n + 1) + (n - int(robot.id))


def _regroup(robot: Robot) -> None:
    """Merge ``dup`` and ``key`` over each group of own active features with one label."""
    st: LabelState = robot.labels
    rows = np.flatnonzero(robot.active)
    if rows.size == 0:
        return
    groups, inv, count = np.unique(st.label[rows], return_inverse=True, return_counts=True)
    dup = np.zeros(groups.size, dtype=bool)
    np.logical_or.at(dup, inv, st.dup[rows])
    dup |= count >= 2
    key = _own_key(robot, count)
    np.maximum.at(key, inv, st.key[rows])
    new_dup, new_key = dup[inv], key[inv]
    st.changed[rows] |= (new_dup != st.dup[rows]) | (new_key != st.key[rows])
    st.dup[rows] = new_dup
    st.key[rows] = new_key
    st.heard[rows] |= count[inv] >= 2


def _send_changed(robot: Robot, send) -> None:
    """The changed features' triples to every robot they are linked to (alive links)."""
    st: LabelState = robot.labels
    sel = robot.link_alive & robot.active[robot.link_r] & st.changed[robot.link_r]
    st.changed[:] = False
    idx = np.flatnonzero(sel)
    if idx.size == 0:
        return
    nbr = robot.link_nbr[idx]
    order = np.argsort(nbr, kind="stable")
    idx, nbr = idx[order], nbr[order]
    idt = _id_dtype(robot)
    for part in np.split(idx, np.flatnonzero(np.diff(nbr)) + 1):
        r = np.unique(robot.link_r[part])
        send(int(robot.link_nbr[part[0]]), KIND,
             {"feat": r.astype(np.int32), "label": st.label[r].astype(idt),
              "dup": st.dup[r].astype(np.uint8), "key": st.key[r].astype(np.int64)})


def start_labels(robot: Robot, iteration: int, send) -> None:
    """Round 0: the active features (as the rows of Sec. III choose them, Sec. IV after
    Cor. 4.4) start with their own id, count one, and send it along their alive links."""
    reset_detection(robot, iteration)
    m = robot.m
    robot.labels = LabelState(label=robot.gid0 + np.arange(m, dtype=np.int64),
                              dup=np.zeros(m, dtype=bool),
                              key=_own_key(robot, np.ones(m, dtype=np.int64)),
                              heard=np.zeros(m, dtype=bool), changed=robot.active.copy())
    robot.stopped = not robot.active.any()
    _send_changed(robot, send)
    _measure(robot)


def labels_step(robot: Robot, inbox: list[Message], send, round_: int = 0) -> None:
    """One round: fold in the neighbours' triples (``min``, ``or``, ``max`` over each alive
    link between two active features), regroup, send what changed."""
    st: LabelState = robot.labels
    sel = robot.link_alive & robot.active[robot.link_r]
    for msg in inbox:
        if msg.kind != KIND:
            continue
        p = msg.payload
        feat = np.asarray(p["feat"], dtype=np.int64)
        mine = np.flatnonzero(sel & (robot.link_nbr == msg.src))
        if mine.size == 0 or feat.size == 0:
            continue
        s = robot.link_s[mine]
        pos = np.minimum(np.searchsorted(feat, s), feat.size - 1)
        ok = feat[pos] == s
        r, pos = robot.link_r[mine][ok], pos[ok]
        if r.size == 0:
            continue
        lab = np.asarray(p["label"], dtype=np.int64)[pos]
        dup = np.asarray(p["dup"], dtype=bool)[pos]
        key = np.asarray(p["key"], dtype=np.int64)[pos]
        old_l, old_d, old_k = st.label[r].copy(), st.dup[r].copy(), st.key[r].copy()
        np.minimum.at(st.label, r, lab)
        np.logical_or.at(st.dup, r, dup)
        np.maximum.at(st.key, r, key)
        st.heard[r] = True
        st.changed[r] |= ((st.label[r] != old_l) | (st.dup[r] != old_d) | (st.key[r] != old_k))
    _regroup(robot)
    _send_changed(robot, send)
    robot.t_stop = int(round_)
    _measure(robot)


def finish_labels(robot: Robot) -> None:
    """The detection's outputs, as :func:`.detection.find_conflictive_sets` sets them."""
    st: LabelState = robot.labels
    n = int(robot.n)
    conflictive = robot.active & st.dup
    robot.conflictive = conflictive
    label = np.full(robot.m, -1, dtype=np.int64)
    label[conflictive] = st.label[conflictive]
    robot.set_label = label
    named = np.flatnonzero(robot.active & ~st.dup & st.heard)
    robot.track_label[named] = st.label[named]
    labs, first = np.unique(label[conflictive], return_index=True)
    keys = st.key[np.flatnonzero(conflictive)[first]]
    robot.root_of_set = dict(zip(labs.tolist(), (n - keys % (n + 1)).tolist(), strict=True))
    robot.stopped = True


def _measure(robot: Robot) -> None:
    robot.peak_memory_bytes = max(robot.peak_memory_bytes,
                                  robot.memory_bytes() + robot.labels.nbytes())


# ------------------------------------------------------------------------------------------
# over the reliable channel (a robot alone: pipeline.consistency.termination)

def start_labels_reliable(robot: Robot, st: ReliableState, iteration: int, now: int) -> None:
    """Round 0 of the flooding with its messages sent reliably (``st`` a
    :class:`~.reliable.ReliableState`); every linked neighbour is waited on (heartbeats)."""
    st.lost_in_phase = False
    st.all_nbrs = set(np.unique(robot.link_nbr[robot.link_alive]).tolist()) - st.chan.lost
    start_labels(robot, iteration, lambda dst, kind, p: st.chan.send(dst, kind, p, now))
    finish_labels(robot)
    st.chan.flush(now, heartbeat_to=sorted(st.all_nbrs))


def labels_round(robot: Robot, st: ReliableState, inbox: list[Message], now: int,
                 phase_round: int) -> None:
    """One network round: the channel's messages folded in (:func:`labels_step`), a silent
    neighbour cut (``robot-lost``), the outcome so far published on the robot (its flags only
    turn true, so the termination wave's ``CONFLICT`` bit may read it every round)."""
    msgs = st.chan.receive(inbox, now)
    lost = st.chan.check_lost(now, st.all_nbrs)
    if lost:
        cut_lost(robot, st, lost, phase_round)
        st.all_nbrs -= set(lost)
    labels_step(robot, msgs, lambda dst, kind, p: st.chan.send(dst, kind, p, now), phase_round)
    finish_labels(robot)
    st.chan.flush(now, heartbeat_to=sorted(st.all_nbrs))


def labels_done(robot: Robot, st: ReliableState) -> bool:
    """Everything this robot sent is acknowledged: when every robot is so, nothing is in
    flight and no value can change again (the phase end of the simulator)."""
    return st.chan.idle()
