"""Decentralized detection of inconsistent associations (Aragüés et al., Sec. III).

Each robot ``i`` keeps ``X_i·(t) = [X_i1(t) … X_in(t)]`` as ONE sparse boolean matrix
``(m_i, m_total)`` whose columns are global feature ids. It starts from eq. (4)
(``X_ii(0) = I``, ``X_ij(0) = 0``), and in every round applies eq. (5),

    X_i·(t+1) = W_ii X_i·(t) + Σ_{k ∈ N_i} W_ik X_k·(t),

with the blocks ``X_k·(t)`` last received from each neighbour, kept boolean (Def. 3.4: any
positive entry becomes ``True``, so ``X_i·(t)`` row ``r`` is the set of features within ``t``
hops of ``f_r^i``). Robot ``i`` stops at the first ``t_i`` with ``X_i·(t_i) ~ X_i·(t_i − 1)``
(Prop. 3.5); since ``W_ii = I`` makes the rows grow monotonically, "nothing changed" is
exactly "the number of non-zeros did not grow". A stopped robot sends nothing more: its
neighbours keep using the last blocks received from it (the paper's rule after Cor. 3.6),
which are final.

Interpretations (stated):

* Message content. Robot ``k`` sends to neighbour ``i`` only the rows ``s`` of ``X_k·(t)`` with
  ``[W_ki]_{s,·} ≠ 0`` — the only rows ``W_ik X_k·(t)`` reads — as ``rows`` (k's local ids),
  CSR ``indptr`` and column ``indices`` (int32). It sends only while it has not stopped.
* Delta messages (the default of the paper's protocol on a lossless network; the paper
  itself sends the whole ``X_k·(t)``, and the result is the same, below). A robot
  sends only the entries of those rows that are new since its last message,
  ``Δ_k·(t) = X_k·(t) ∖ X_k·(t−1)`` (``Δ_k·(0) = X_k·(0)``), and only the rows with a new
  entry; a neighbour with nothing new gets no message. The receiver needs no copy of its
  neighbours' blocks: since ``X_i·(t) ⊇ W_ik X_k·(t−1)`` (it applied eq. 5 in round ``t``),

      X_i·(t+1) = X_i·(t) + Σ_k W_ik X_k·(t) = X_i·(t) + Σ_k W_ik Δ_k·(t),

  so eq. (5) on the deltas of the round gives exactly ``X_i·(t+1)``, Prop. 3.5 fires at the
  same ``t_i``, and a silent (stopped) neighbour, whose ``X_k·`` no longer changes, adds
  nothing — the paper's "use the last matrix received". Each message still carries
  ``rows``, ``indptr`` and ``indices``: what the receiver needs to decode it. This relies on
  every message arriving in the next round; on a faulty network the robots send whole
  blocks (:class:`~.protocols.ProtocolOptions`).
* Rows. Only *active* features get a row: in the first iteration every feature with a link
  (an isolated feature's row is its own id and can never be conflictive); in later iterations
  the features that were conflictive and left unassigned by Alg. 1, whose links all stay
  among themselves (Sec. IV, after Cor. 4.4: "the detection algorithm can be executed on the
  subgraph defined by this smaller subset of features").

Conflictive features follow rules (8) and (9), which together say: row ``r`` holds two
columns of one camera. Each conflictive set is named by its smallest global feature id, which
every robot touching it computes identically; its root follows eq. (10).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.sparse as sp

from pipeline.consistency.robot import Robot
from pipeline.transport import Message

__all__ = ["start_detection", "init_detection", "reset_detection", "set_identity_rows",
           "detection_step", "eq5_next", "eq5_step",
           "send_blocks", "blocks_from_payload", "find_conflictive_sets"]

Send = Callable[[int, str, dict], None]


def _index_dtype(robot: Robot):
    return np.int32 if robot.m_total < 2**31 else np.int64


def start_detection(robot: Robot, iteration: int, send: Send) -> None:
    """Round 0 of a detection: initialise ``X_i·(0)`` by eq. (4) and send it.

    Parameters
    ----------
    robot : Robot
    iteration : int — detection/resolution iteration (1-based)
    send : callable ``(dst, kind, payload)`` bound to this robot
    """
    rows = init_detection(robot, iteration)
    robot.stopped = rows.size == 0
    if not robot.stopped:
        send_blocks(robot, send)
    robot.measure_memory()


def init_detection(robot: Robot, iteration: int) -> np.ndarray:
    """Choose the active rows and set ``X_i·(0)`` by eq. (4); returns the active rows (R,).

    Resets the detection outputs (``conflictive``, ``set_label``, ``root_of_set``,
    ``t_stop``) and the blocks received (``last_blocks``).
    """
    rows = reset_detection(robot, iteration)
    set_identity_rows(robot, rows)
    return rows


def reset_detection(robot: Robot, iteration: int) -> np.ndarray:
    """:func:`init_detection` but ``X``: the active rows (R,), the outputs reset."""
    robot.iteration = iteration
    has_link = np.zeros(robot.m, dtype=bool)
    has_link[robot.link_r[robot.link_alive]] = True
    robot.active = robot.candidates & has_link & (robot.component < 0)
    rows = np.flatnonzero(robot.active)
    robot.last_blocks = {}
    robot.conflictive = np.zeros(robot.m, dtype=bool)
    robot.set_label = np.full(robot.m, -1, dtype=np.int64)
    robot.root_of_set = {}
    robot.t_stop = 0
    return rows


def set_identity_rows(robot: Robot, rows: np.ndarray) -> None:
    """``X_i·(0)`` by eq. (4): ``X_ii(0) = I``, ``X_ij(0) = 0`` on the rows ``rows``; all new."""
    indptr = np.zeros(robot.m + 1, dtype=np.int64)
    indptr[rows + 1] = 1
    indptr = np.cumsum(indptr)
    robot.X = sp.csr_matrix((np.ones(rows.size, dtype=bool), (robot.gid0 + rows).astype(np.int64),
                             indptr), shape=(robot.m, robot.m_total))
    robot.X_new = robot.X  # everything in X_i·(0) is new


def send_blocks(robot: Robot, send: Send) -> None:
    """Send each linked neighbour the rows of ``robot.X_new`` it multiplies by (eq. 5).

    ``X_new`` is ``X_i·(t)`` itself (whole blocks) or its entries new since the last message
    (delta messages, see the module notes). One ``blocks`` message per neighbour ``k`` that
    has a non-empty row to receive: ``rows`` (this robot's local ids ``r`` with
    ``[W_ik]_{r,·} ≠ 0`` and a non-empty row), CSR ``indptr`` and column ``indices``.
    """
    src = robot.X_new
    sel = robot.link_alive & robot.active[robot.link_r]
    sel &= np.diff(src.indptr)[robot.link_r] > 0
    sel = np.flatnonzero(sel)
    if sel.size == 0:
        return
    nbr = robot.link_nbr[sel]
    cut = np.flatnonzero(np.diff(nbr)) + 1
    idt = _index_dtype(robot)
    for part in np.split(sel, cut):
        rows = np.unique(robot.link_r[part])
        blk = src[rows]
        send(int(robot.link_nbr[part[0]]), "blocks",
             {"rows": rows.astype(np.int32), "indptr": blk.indptr.astype(idt),
              "indices": blk.indices.astype(idt)})


def blocks_from_payload(robot: Robot, payload: dict) -> tuple[np.ndarray, sp.csr_matrix]:
    """A neighbour's ``blocks`` message as ``(rows (R,) int32, X_k·(t)[rows] (R, m_total) csr)``."""
    nrows = payload["rows"].shape[0]
    blk = sp.csr_matrix((np.ones(payload["indices"].shape[0], dtype=bool), payload["indices"],
                         payload["indptr"]), shape=(nrows, robot.m_total))
    return payload["rows"], blk


def eq5_step(robot: Robot, blocks: dict, t_next: int, delta: bool = False) -> bool:
    """One step of eq. (5) to ``X_i·(t_next)``, or the stop of Prop. 3.5; True if stopped.

    Parameters
    ----------
    robot : Robot
    blocks : dict ``k -> (rows, block)`` — the neighbours' ``X_k·(t_next - 1)``, or with
        ``delta`` their new entries ``Δ_k·(t_next - 1)`` (see :func:`eq5_next`)
    t_next : int — the round ``t + 1`` being computed
    delta : bool — keep the new entries in ``robot.X_new`` (delta messages); else
        ``robot.X_new`` is ``robot.X`` (whole blocks are sent)

    Notes
    -----
    Prop. 3.5: robot ``i`` stops at the first ``t_i`` with ``X_i·(t_i) ~ X_i·(t_i − 1)``;
    ``W_ii = I`` makes the rows grow monotonically, so "nothing changed" is "the number of
    non-zeros did not grow". On a stop, rules (8)-(9) and eq. (10) run
    (:func:`find_conflictive_sets`); otherwise ``robot.X`` becomes ``X_i·(t_next)``.
    """
    X_next = eq5_next(robot, blocks)
    if X_next.nnz == robot.X.nnz:
        robot.stopped = True
        robot.t_stop = int(t_next)
        robot.X_new = sp.csr_matrix(robot.X.shape, dtype=bool) if delta else robot.X
        find_conflictive_sets(robot)
        return True
    # X(t) ⊆ X(t+1) (W_ii = I): the entries that differ are the new ones
    robot.X_new = (X_next != robot.X).tocsr() if delta else X_next
    robot.X = X_next
    return False


def detection_step(robot: Robot, inbox: list[Message], send: Send, round_: int,
                   delta: bool = False) -> None:
    """One round ``t = round_`` (≥ 1) of eq. (5) for one robot; stops by Prop. 3.5.

    Whole blocks (``delta`` False): a silent neighbour's last received blocks are used
    (Sec. III, after Cor. 3.6). Delta messages: eq. (5) runs on the deltas of this round
    alone (module notes), and a stopped robot drops them. Once stopped, the robot neither
    computes nor sends.
    """
    if robot.stopped:
        return
    received = {msg.src: blocks_from_payload(robot, msg.payload) for msg in inbox
                if msg.kind == "blocks"}
    if delta:
        robot.last_blocks = received
    else:
        robot.last_blocks.update(received)
    if not eq5_step(robot, robot.last_blocks, round_, delta):
        send_blocks(robot, send)
    robot.measure_memory()
    if delta and robot.stopped:
        robot.last_blocks = {}


def eq5_next(robot: Robot, blocks: dict) -> sp.csr_matrix:
    """``X_i·(t+1)`` by eq. (5), boolean (Def. 3.4), from the neighbours' blocks ``X_k·(t)``.

    Parameters
    ----------
    robot : Robot — reads ``X``, its alive links and its active rows
    blocks : dict ``k -> (rows (R_k,) int32, block (R_k, m_total) csr bool)``
        The rows of ``X_k·(t)`` that neighbour ``k`` sent (rows linked to this robot).

    Returns
    -------
    scipy.sparse.csr_matrix, (m_i, m_total) bool, indices sorted
    """
    sel = robot.link_alive & robot.active[robot.link_r]
    p_rows, p_cols, pieces = [], [], []
    base = 0
    for k, (rows, blk) in blocks.items():
        mine = np.flatnonzero(sel & (robot.link_nbr == k))
        if mine.size == 0 or rows.size == 0:
            continue
        s = robot.link_s[mine]
        pos = np.minimum(np.searchsorted(rows, s), rows.size - 1)
        ok = rows[pos] == s  # a row the neighbour has not sent (only under faults) is skipped
        p_rows.append(robot.link_r[mine][ok])
        p_cols.append(base + pos[ok])
        pieces.append(blk)
        base += rows.size
    X = robot.X
    if pieces:
        r = np.concatenate(p_rows)
        c = np.concatenate(p_cols)
        P = sp.csr_matrix((np.ones(r.size, dtype=bool), (r, c)), shape=(robot.m, base))
        # eq. (5), boolean (Def. 3.4): X(t+1) = X(t) + Σ_k W_ik X_k(t)
        X_next = (X + P @ sp.vstack(pieces, format="csr")).tocsr()
    else:
        X_next = X.copy()
    X_next.sort_indices()
    return X_next


def find_conflictive_sets(robot: Robot) -> None:
    """Rules (8) and (9) on ``X_i·(t_i)`` and the root of every set touched (eq. 10).

    Sets ``robot.conflictive`` (m_i,), ``robot.set_label`` (m_i,) — the smallest global id in
    the feature's conflictive set, ``-1`` otherwise — ``robot.root_of_set``
    ``{label: root robot}``, and ``robot.track_label`` of the active features found
    non-conflictive (see :meth:`Robot.final_tracks`).
    """
    X = robot.X
    X.sort_indices()
    counts = np.diff(X.indptr)
    row = np.repeat(np.arange(robot.m), counts)
    cam = np.searchsorted(robot.offsets, X.indices, side="right") - 1
    # rule (8): another own feature in row r; rule (9): two features of one robot j in row r.
    # Own column gid(r) is always in row r, so both read: a camera appears twice in the row.
    twice = (row[1:] == row[:-1]) & (cam[1:] == cam[:-1])
    conflictive = np.zeros(robot.m, dtype=bool)
    conflictive[row[1:][twice]] = True
    robot.conflictive = conflictive
    # a non-conflictive row is the feature's whole association set: name its track by the
    # set's smallest global id (indices sorted), the same at every robot of the set
    named = np.flatnonzero(robot.active & ~conflictive & (counts >= 2))
    robot.track_label[named] = X.indices[X.indptr[named]]
    label = np.full(robot.m, -1, dtype=np.int64)
    crow = np.flatnonzero(conflictive)
    if crow.size == 0:
        robot.set_label = label
        robot.root_of_set = {}
        return
    label[crow] = X.indices[X.indptr[crow]]  # smallest global id of the set (indices sorted)
    robot.set_label = label
    labels, first = np.unique(label[crow], return_index=True)
    reps = crow[first]
    sub = X[reps]
    srow = np.repeat(np.arange(reps.size), np.diff(sub.indptr))
    scam = np.searchsorted(robot.offsets, sub.indices, side="right") - 1
    # features per (set, robot): m~_j of Def. 4.1, by run lengths (cams sorted within a row)
    start = np.flatnonzero(np.r_[True, (srow[1:] != srow[:-1]) | (scam[1:] != scam[:-1])])
    run_len = np.diff(np.r_[start, srow.size])
    run_set, run_cam = srow[start], scam[start]
    # eq. (10): most features; ties to the lowest robot id
    order = np.lexsort((run_cam, -run_len, run_set))
    firsts = order[np.r_[True, run_set[order][1:] != run_set[order][:-1]]]
    robot.root_of_set = dict(zip(labels.tolist(), run_cam[firsts].tolist(), strict=True))
