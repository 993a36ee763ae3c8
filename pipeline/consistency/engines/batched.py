"""Batched evaluation of the robots' detection (Sec. III, eq. 5) in the in-process simulator.

The per-robot engine (:func:`.phases.run_phase`) steps every robot in every round: each robot
turns its inbox into sparse blocks, applies eq. (5) and slices the rows for each neighbour.
That is the code the robots run under faults and over a real middleware. On the simulator's
lossless static network with the paper's protocol and delta messages
(:mod:`.detection`, module notes), this module computes the *same* updates of all robots at
once: one sparse product per round over the rows of every robot, stacked.

Why it obeys the one rule (docs/DESIGN.md: a robot sees only its own state and its inbox)
    Stack every robot's active rows into one matrix ``X`` (rows: the active features of
    robot 0, then robot 1, ...; columns: active features). Row ``r`` of robot ``i`` of the
    round's product ``P Δ(t)`` is ``Σ_k [W_ik]_{r,s} Δ_k(t)_{s,·}``: the entries of ``P`` in
    that row are robot ``i``'s own links ``W_ik`` (alive, active at ``i``, and restricted to
    the rows ``s`` that robot ``k`` sends to ``i`` — exactly the rows the per-robot receiver
    finds in its messages), and the rows ``Δ_k(t)_{s,·}`` it reads are what robot ``k``'s
    delta message to ``i`` carries in round ``t``: k's entries new since its last message
    (:func:`~.detection.send_blocks`). So each robot's rows of ``X(t+1) = X(t) + P Δ(t)``
    read only its own rows of ``X(t)``, its own ``W`` and its inbox of the round; no row ever
    reads another robot's state that was not sent to it. The rows of a robot that has
    stopped (Prop. 3.5) are not updated and it sends nothing, as in
    :func:`~.detection.detection_step`. The stop test, rules (8)–(9), the set names and
    roots of eq. (10) are evaluated row by row on each robot's own rows, as
    :func:`~.detection.find_conflictive_sets` does.

Equivalence (tested: ``tests/pipeline/consistency/engines/test_batched.py``)
    Same ``X``, ``t_stop``, conflictive features, set labels, roots and track labels in every
    robot, same rounds, and the same messages and bytes: each delta message robot ``k`` would
    send to ``i`` is counted (:meth:`~pipeline.transport.Transport.count`) with the size
    :func:`~.detection.send_blocks` gives it (header, ``rows`` int32, ``indptr`` and
    ``indices`` in the robot's index type). Each robot's peak memory is computed with the
    formula of :meth:`~.robot.Robot.memory_bytes` on the state it would hold in each round.

Resolution (Alg. 1): :func:`run_resolution` (:mod:`.batched_resolution`) evaluates every
robot's rounds on the link tables stacked, under the same rule.

Where it applies (:func:`batched_applies`): the in-process :class:`Network` with no fault
switch on, the paper's protocol with delta messages. Everywhere else (faults, the reliable
protocol, robots as threads or processes) the robots run one by one.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from pipeline.consistency.detection import reset_detection, set_identity_rows
from pipeline.consistency.engines.batched_resolution import run_resolution
from pipeline.consistency.keys import isin_sorted, ranges
from pipeline.consistency.protocols import PaperProtocol
from pipeline.consistency.robot import Robot
from pipeline.errors import StageStalledError
from pipeline.transport import HEADER_BYTES, Transport
from pipeline.transport.simulated import Network

__all__ = ["batched_applies", "run_detection", "run_resolution"]

_EMPTY = np.zeros(0, dtype=np.int64)


def batched_applies(network: Transport, protocol) -> bool:
    """True where the batched evaluation gives the per-robot results: the in-process
    simulator with no fault on, and the paper's protocol with delta messages."""
    return (type(network) is Network and not network.faulty
            and isinstance(protocol, PaperProtocol) and protocol.delta)


class _SortedKeys:
    """A growing set of int64 keys: a large sorted run and a small recent one, merged when
    the recent run exceeds an eighth of the large one (amortized linear time)."""

    def __init__(self, keys: np.ndarray) -> None:
        self.main = keys
        self.recent = _EMPTY

    def contains(self, q: np.ndarray) -> np.ndarray:
        return isin_sorted(q, self.main) | isin_sorted(q, self.recent)

    def add(self, new_sorted: np.ndarray) -> None:
        self.recent = _merge(self.recent, new_sorted)
        if self.recent.size * 8 > self.main.size:
            self.main = _merge(self.main, self.recent)
            self.recent = _EMPTY

    def all(self) -> np.ndarray:
        return _merge(self.main, self.recent)


class _DenseKeys:
    """The same set of keys ``row << shift | col`` as a boolean array of ``A << shift``
    entries, for a
    small ``A`` (:data:`DENSE_KEYS_MAX` at most): a lookup per key instead of a search."""

    def __init__(self, keys: np.ndarray, A: int) -> None:
        self.has = np.zeros(A << _shift(A), dtype=bool)
        self.has[keys] = True

    def contains(self, q: np.ndarray) -> np.ndarray:
        return self.has[q]

    def add(self, new_sorted: np.ndarray) -> None:
        self.has[new_sorted] = True

    def all(self) -> np.ndarray:
        return np.flatnonzero(self.has).astype(np.int64)


#: largest ``A²`` (bytes) for which the detection keeps ``X`` as a dense boolean array
DENSE_KEYS_MAX = 1 << 24

#: most (reader, entry) pairs a round of eq. (5) lists before removing repeats (:func:`_step`;
#: 32 MB of int64 keys); a round with more is one sparse matrix product
EXPAND_KEYS_MAX = 1 << 22


class _Balls:
    """The same set of keys when ``P`` is symmetric (:attr:`_Team.symmetric`): the deltas of
    every round, of which only the last two answer :meth:`contains`.

    Why two suffice. With ``P`` symmetric it is the adjacency of an undirected graph on the
    active features, and row ``r`` of ``X(t)`` is the ball ``B(r, t)`` of radius ``t`` about
    ``r`` (eq. 5 with ``W_ii = I``; a stopped robot's rows are whole components, Prop. 3.5, so
    its silence changes no ball), and its delta ``Δ_r(t)`` is the sphere ``S(r, t)``. A key
    ``(r, c)`` that round ``t + 1`` computes comes from a neighbour ``s`` of ``r`` with
    ``c ∈ Δ_s(t) = S(s, t)``, so ``t - 1 ≤ d(r, c) ≤ t + 1``: it is already in ``X(t)`` iff
    ``c ∈ S(r, t) ∪ S(r, t - 1) = Δ_r(t) ∪ Δ_r(t - 1)``. (Round ``t + 1`` computes the rows of
    robots still running, whose rows were computed in rounds ``t`` and ``t - 1`` too.)
    """

    def __init__(self, keys: np.ndarray) -> None:
        self.runs = [keys]
        self.last, self.before = keys, _EMPTY

    def contains(self, q: np.ndarray) -> np.ndarray:
        # q, last and before sorted and unique, last and before disjoint: merge the three
        # runs (a stable sort merges sorted runs in linear time); a key of q also in last or
        # before lands right after its twin
        known = self.last.size + self.before.size
        c = np.concatenate([self.last, self.before, q])
        order = np.argsort(c, kind="stable")
        c = c[order]
        out = np.zeros(q.size, dtype=bool)
        out[order[1:][c[1:] == c[:-1]] - known] = True
        return out

    def add(self, new_sorted: np.ndarray) -> None:
        self.runs.append(new_sorted)
        self.last, self.before = new_sorted, self.last

    def all(self) -> np.ndarray:
        out = np.concatenate(self.runs)
        out.sort(kind="stable")  # sorted runs: merged
        return out



def _shift(A: int) -> int:
    """Bits of a column in the keys ``row << shift | col`` of ``A`` rows and columns."""
    return max(int(A).bit_length(), 1)


def _unique(a: np.ndarray) -> np.ndarray:
    """Sorted unique values of an int64 array (by sorting: faster here than hashing)."""
    a = np.sort(a)
    return a[np.r_[True, a[1:] != a[:-1]]] if a.size else a


def _merge(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    if a.size == 0:
        return b
    if b.size == 0:
        return a
    out = np.concatenate([a, b])
    out.sort(kind="stable")  # two sorted runs: linear
    return out


class _Team:
    """The robots' own tables, stacked for one detection (compact ids of the active rows).

    Attributes
    ----------
    A : int — active features of all robots (rows and columns of the stacked ``X``)
    gid : (A,) int64 — global id of each active feature (sorted: robot by robot)
    owner : (A,) int64 — its robot
    row_bounds : (n + 1,) int64 — robot ``i``'s rows are ``row_bounds[i]:row_bounds[i+1]``
    readers_ptr, readers : the matrix ``P`` (A, A) by column, CSR of its transpose: row
        ``(i, r)`` of ``P`` holds ``[W_ik]_{r,s}`` for the rows ``s`` robot ``k`` sends to ``i``
    send_ptr, send_pair_by_row : what each row's owner sends, by row: row ``s`` goes in the
        messages ``send_pair_by_row[send_ptr[s]:send_ptr[s+1]]`` (pairs ``(k, i)`` numbered
        ``0..n_pairs-1``)
    pair_dst : (n_pairs,) int64 — receiving robot of each pair
    symmetric : bool — every alive link of an active row is alive at its other end too (then
        ``P`` is symmetric; :func:`run_detection` uses it)
    """

    def __init__(self, robots: list[Robot]) -> None:
        n = len(robots)
        self.n = n
        act = [np.flatnonzero(rb.active) for rb in robots]
        counts = np.array([a.size for a in act], dtype=np.int64)
        self.row_bounds = np.concatenate([[0], np.cumsum(counts)])
        self.A = A = int(self.row_bounds[-1])
        self.gid = np.concatenate([rb.gid0 + a for rb, a in zip(robots, act, strict=True)]
                                  + [_EMPTY]).astype(np.int64)
        self.owner = np.repeat(np.arange(n, dtype=np.int64), counts)
        m_total = robots[0].m_total if robots else 0
        offsets = robots[0].offsets if robots else np.zeros(1, dtype=np.int64)
        compact = np.full(m_total, -1, dtype=np.int64)  # the public layout: one id per feature
        compact[self.gid] = np.arange(A)
        # every robot's alive links of its active rows, in its table order (nbr, s):
        # (own robot, own row, neighbour k, k's row s)
        sel = [rb.link_alive & rb.active[rb.link_r] for rb in robots]
        own = np.repeat(np.arange(n, dtype=np.int64), [int(x.sum()) for x in sel])
        r = np.concatenate([rb.link_r[x] for rb, x in zip(robots, sel, strict=True)] + [_EMPTY])
        k = np.concatenate([rb.link_nbr[x] for rb, x in zip(robots, sel, strict=True)] + [_EMPTY])
        s = np.concatenate([rb.link_s[x] for rb, x in zip(robots, sel, strict=True)] + [_EMPTY])
        row = compact[offsets[own] + r]  # active: always found
        col = compact[offsets[k] + s]
        # what each robot sends (send_blocks): each active row with an alive link to the
        # neighbour, once (one-to-one, Assumption 2.2: a row has one link per neighbour); the
        # table order groups the entries by (robot, neighbour): one group per message
        head = np.r_[True, (own[1:] != own[:-1]) | (k[1:] != k[:-1])][:k.size]
        pair = np.cumsum(head) - 1
        self.pair_dst = k[head]
        # Symmetric tables: every entry (i, r, k, s) has its mate (k, s, i, r) among the
        # entries (both ends alive, both rows active). The entries are in (i, k, s) order, so
        # this holds iff the mates' keys, sorted, are the entries' keys. Then robot k sends
        # row s to i (its mate is an alive link of an active row) and i multiplies by it:
        # P[r, s] = 1 for every entry, P is symmetric, and the rows robot k sends are P's.
        span = int(max((rb.m for rb in robots), default=0)) + 1
        self.symmetric = bool(n * n * span < 2**62) and np.array_equal(
            (own * n + k) * span + s, np.sort((k * n + own) * span + r))
        if self.symmetric:
            # P by row: who reads row s's delta (P[s, ·] = P[·, s]) and, with each entry, the
            # message (pair) that carries row s to that reader
            Pm = sp.csr_matrix((pair + 1, (row, col)), shape=(A, A))
            self.readers_ptr = self.send_ptr = Pm.indptr.astype(np.int64)
            self.readers = Pm.indices.astype(np.int64)
            self.send_pair_by_row = Pm.data.astype(np.int64) - 1
            self.P = sp.csr_matrix((np.ones(self.readers.size, dtype=bool), Pm.indices,
                                    Pm.indptr), shape=(A, A))
            return
        sends = sp.csr_matrix((np.ones(row.size, dtype=bool), (row, k)), shape=(A, max(n, 1)))
        # what each robot multiplies by (eq5_next): its links to rows the neighbour sends it
        ok = col >= 0
        ok[ok] = np.asarray(sends[col[ok], own[ok]]).ravel()
        # P[r, s] = [W_ik]_{r,s}, stored by column: who multiplies row s (its delta's readers)
        PT = sp.csr_matrix((np.ones(int(ok.sum()), dtype=bool), (col[ok], row[ok])),
                           shape=(A, A))
        self.readers_ptr, self.readers = PT.indptr.astype(np.int64), PT.indices.astype(np.int64)
        self.P = PT.T.tocsr()  # by row: the rows each row of P Δ reads
        # the send entries of each row, to count a round's messages from its new rows only
        by_row = np.argsort(row, kind="stable")
        self.send_pair_by_row = pair[by_row]
        self.send_ptr = np.concatenate([[0], np.cumsum(np.bincount(row, minlength=A))])

    def messages(self, rows: np.ndarray, count: np.ndarray, idx_size: int):
        """The delta messages of a round whose rows ``rows`` (R,) have ``count`` (R,) > 0 new
        entries each (the other rows none).

        Returns ``(messages, bytes, received (n,) bytes each robot holds as received blocks)``
        — sizes as :func:`~.detection.send_blocks` and :func:`~.detection.blocks_from_payload`
        give them.
        """
        start, stop = self.send_ptr[rows], self.send_ptr[rows + 1]
        pair = self.send_pair_by_row[ranges(start, stop)]
        d = np.repeat(count, stop - start)
        n_pairs = self.pair_dst.size
        R = np.bincount(pair, minlength=n_pairs)
        nnz = np.bincount(pair, weights=d, minlength=n_pairs).astype(np.int64)
        sent = R > 0
        R, nnz, dst = R[sent], nnz[sent], self.pair_dst[sent]
        payload = 4 * R + idx_size * (R + 1) + idx_size * nnz  # rows int32, indptr, indices
        held = payload + nnz  # the receiver's csr also holds one bool per entry
        received = np.bincount(dst, weights=held, minlength=self.n).astype(np.int64)
        return int(sent.sum()), int((HEADER_BYTES + payload).sum()), received


def run_detection(robots: list[Robot], network: Transport, protocol: PaperProtocol,
                  iteration: int, max_rounds: int | None = None, on_round=None) -> dict:
    """One detection (Sec. III) of all robots, evaluated in batch; returns what
    :func:`.phases.run_phase` returns for it.

    Parameters
    ----------
    robots : list[Robot], (n,)
    network : Transport — the in-process :class:`Network` (clock advanced, traffic counted)
    protocol : PaperProtocol — with ``delta`` on (see :func:`batched_applies`)
    iteration : int — detection/resolution iteration (1-based)
    max_rounds : int or None — cap of the phase (default: the protocol's)
    on_round : callable ``(round) -> None`` or None — progress report

    Returns
    -------
    dict — ``rounds``, ``start_round``, ``lost`` (False), ``t_stop`` (n,),
    ``conflictive_features``
    """
    n = len(robots)
    start_round = int(network.round)
    for rb in robots:
        # init_detection, but X(0): the rows of a robot that runs are set at the end (_finish)
        rows = reset_detection(rb, iteration)
        rb.stopped = rows.size == 0
        if rb.stopped:
            set_identity_rows(rb, rows)
    team = _Team(robots)
    A = team.A
    idx_size = np.dtype(np.int32 if (robots and robots[0].m_total < 2**31) else np.int64).itemsize
    m = np.array([rb.m for rb in robots], dtype=np.int64)
    fixed = np.array([rb.fixed_bytes() for rb in robots], dtype=np.int64)
    idx_bytes = (m + 1) * idx_size  # indptr of an (m_i, m_total) csr

    def csr_bytes(nnz):
        return nnz * (1 + idx_size) + idx_bytes

    # round 0 (start_detection): X(0) = I on the active rows (eq. 4), all of it sent
    nnz_x = np.diff(team.row_bounds)
    # keys of X: row << sh | col (a shift and a mask to split them: cheaper than // and %)
    sh = _shift(A)
    diag = np.arange(A, dtype=np.int64)
    diag = diag << sh | diag
    lone = np.zeros(A, dtype=bool)
    if team.symmetric:
        # a row whose component is one link (its one neighbour has no other): its ball is
        # complete at radius 1, so round 1 adds its neighbour and nothing else ever comes;
        # such rows are left out of the keys computed round by round and added in round 1
        deg = np.diff(team.readers_ptr)
        one = np.flatnonzero(deg == 1)
        mate = team.readers[team.readers_ptr[one]]
        lone[one[deg[mate] == 1]] = True
        X = _Balls(diag[~lone])
        X.runs += [diag[lone], np.flatnonzero(lone) << sh | mate[deg[mate] == 1]]  # final keys
    else:
        X = _DenseKeys(diag, A) if A << sh <= DENSE_KEYS_MAX else _SortedKeys(diag)
    delta = diag[~lone]
    lone_rows = np.flatnonzero(lone)
    running = nnz_x > 0
    t_stop = np.zeros(n, dtype=np.int64)
    peak = np.array([rb.peak_memory_bytes for rb in robots], dtype=np.int64)
    peak = np.maximum(peak, fixed + csr_bytes(nnz_x))  # X_new is X itself
    stop_mem = np.zeros(n, dtype=np.int64)
    msgs, nbytes, received = team.messages(np.arange(A), np.ones(A, dtype=np.int64), idx_size)
    if msgs:
        network.count("blocks", msgs, nbytes)
    cap = protocol.max_rounds("detection", robots) if max_rounds is None else max_rounds
    t = 0
    while running.any():
        network.end_round()
        t += 1
        if on_round is not None:
            on_round(t)
        # eq. (5) on the deltas of round t - 1, every running robot's rows at once
        new = _step(team, delta, running)
        new = new[~X.contains(new)]
        # the rows with new entries and how many (keys sorted: rows in runs)
        new_rows = new >> sh
        head = np.flatnonzero(new_rows[1:] != new_rows[:-1]) + 1
        rows = new_rows[np.r_[0, head]] if new.size else _EMPTY
        count = np.diff(np.r_[0, head, new.size]) if new.size else _EMPTY
        if t == 1 and lone_rows.size:  # the rows of one-link components take their neighbour
            rows = np.r_[rows, lone_rows]
            count = np.r_[count, np.ones(lone_rows.size, dtype=np.int64)]
        new_per_robot = np.bincount(team.owner[rows], weights=count, minlength=n).astype(np.int64)
        stops = running & (new_per_robot == 0)
        go = running & ~stops
        X.add(new)
        delta = new
        nnz_x = nnz_x + new_per_robot
        # memory after the step: X, X_new (empty on a stop), the blocks received this round
        mem = fixed + csr_bytes(nnz_x) + received + np.where(stops, idx_bytes,
                                                            csr_bytes(new_per_robot))
        peak[go] = np.maximum(peak[go], mem[go])
        stop_mem[stops] = mem[stops]
        t_stop[stops] = t
        running = go
        msgs, nbytes, received = team.messages(rows, count, idx_size)
        if msgs:
            network.count("blocks", msgs, nbytes)
        if t > cap:
            raise StageStalledError(f"detection did not end within {cap} rounds")
    ran = np.diff(team.row_bounds) > 0
    n_sets = _finish(robots, team, X.all(), t_stop, ran)
    peak[ran] = np.maximum(peak[ran], stop_mem[ran] + 16 * n_sets[ran])
    for rb in robots:
        rb.peak_memory_bytes = int(peak[rb.id])
        network.note_memory(rb.id, rb.peak_memory_bytes)
    return dict(rounds=t, start_round=start_round, lost=False, t_stop=t_stop,
                conflictive_features=int(sum(int(rb.conflictive.sum()) for rb in robots)))



def _step(team: _Team, delta: np.ndarray, running: np.ndarray) -> np.ndarray:
    """Keys (row << shift | col) of the rows of running robots of ``P Δ``, sorted and unique.

    ``Δ`` is given by its sorted keys; each entry ``(s, c)`` of ``Δ`` reaches the rows ``r``
    with ``P[r, s]`` (the robots that read row ``s`` of the sender's delta message).

    Two evaluations of the same set of keys. Listing every (reader, entry) pair and removing
    the repeats holds one key per path to an entry: fastest where few paths repeat (sparse
    graphs), but on a dense one about a hundred times the result (the 101-frame hotel input:
    7.6 GB at the peak). Past :data:`EXPAND_KEYS_MAX` pairs the round is SciPy's sparse
    product of boolean matrices instead (a sum is an "or"), whose memory is its result's.
    """
    if delta.size == 0:
        return _EMPTY
    A = team.A
    sh = _shift(A)
    s, c = delta >> sh, delta & ((1 << sh) - 1)
    start, stop = team.readers_ptr[s], team.readers_ptr[s + 1]
    if int((stop - start).sum()) <= EXPAND_KEYS_MAX:
        pos = ranges(start, stop)
        r = team.readers[pos]
        c = np.repeat(c, stop - start)
        # a row's own column is in X from round 0 (eq. 4): not computed again
        return _unique((r << sh | c)[running[team.owner[r]] & (r != c)])
    D = sp.csr_matrix((np.ones(s.size, dtype=bool), c,
                       np.concatenate([[0], np.cumsum(np.bincount(s, minlength=A))])),
                      shape=(A, A))
    rows = np.flatnonzero(running[team.owner])
    Q = team.P[rows] @ D
    Q.sort_indices()
    r = np.repeat(rows, np.diff(Q.indptr))
    keys = r << sh | Q.indices.astype(np.int64)  # sorted: rows ascending, columns within
    return keys[r != Q.indices]


def _finish(robots: list[Robot], team: _Team, keys: np.ndarray, t_stop: np.ndarray,
            ran: np.ndarray) -> np.ndarray:
    """Hand every robot that ran its final state: ``X``, the stop, rules (8)–(9), eq. (10).

    Row by row as :func:`~.detection.find_conflictive_sets` on each robot's own ``X_i·``;
    returns the number of sets each robot knows (its ``root_of_set``), ``(n,)``.
    """
    A, gid, owner = team.A, team.gid, team.owner
    sh = _shift(A)
    rows, cols = keys >> sh, keys & ((1 << sh) - 1)
    counts = np.bincount(rows, minlength=A)
    starts = np.concatenate([[0], np.cumsum(counts)])
    cam = owner[cols]
    # rules (8)-(9): a camera twice in a row (columns sorted within a row)
    twice = (rows[1:] == rows[:-1]) & (cam[1:] == cam[:-1])
    conflictive = np.zeros(A, dtype=bool)
    conflictive[rows[1:][twice]] = True
    first = gid[cols[starts[:-1][counts > 0]]] if A else _EMPTY
    smallest = np.full(A, -1, dtype=np.int64)
    smallest[counts > 0] = first  # smallest global id of each row
    # eq. (10) on one representative row per (robot, set): its lowest conflictive row
    crow = np.flatnonzero(conflictive)
    order = np.lexsort((crow, smallest[crow], owner[crow]))
    crow = crow[order]
    head = np.r_[True, (owner[crow][1:] != owner[crow][:-1])
                 | (smallest[crow][1:] != smallest[crow][:-1])] if crow.size else \
        np.zeros(0, dtype=bool)
    reps = crow[head]
    root = _roots(reps, starts, counts, cam)
    rep_bounds = np.searchsorted(owner[reps], np.arange(team.n + 1))
    n_sets = np.diff(rep_bounds)
    idt = np.int32 if (robots and robots[0].m_total < 2**31) else np.int64
    if not robots:
        return n_sets
    # every robot's rows laid out by global feature id (robot by robot, as the keys): a
    # robot's X, flags and labels are then slices
    m_total, offsets = robots[0].m_total, robots[0].offsets
    per_feature = np.zeros(m_total, dtype=np.int64)
    per_feature[gid] = counts
    ptr = np.zeros(m_total + 1, dtype=np.int64)
    np.cumsum(per_feature, out=ptr[1:])
    indices = gid.astype(idt)[cols]
    conflictive_f = np.zeros(m_total, dtype=bool)
    conflictive_f[gid] = conflictive
    label_f = np.full(m_total, -1, dtype=np.int64)
    label_f[gid[conflictive]] = smallest[conflictive]
    named_f = np.zeros(m_total, dtype=bool)
    named_f[gid] = ~conflictive & (counts >= 2)
    smallest_f = np.full(m_total, -1, dtype=np.int64)
    smallest_f[gid] = smallest
    for rb in robots:
        i = rb.id
        if not ran[i]:
            continue  # no active row: stopped at round 0, nothing evaluated (start_detection)
        o0, o1 = int(offsets[i]), int(offsets[i + 1])
        ka, kb = int(ptr[o0]), int(ptr[o1])
        rb.X = sp.csr_matrix((np.ones(kb - ka, dtype=bool), indices[ka:kb].copy(),
                              (ptr[o0:o1 + 1] - ka).astype(idt)), shape=(rb.m, rb.m_total),
                             copy=False)
        if rb.X_new is rb.X or rb.X_new.nnz:  # else already empty (a stop): kept
            rb.X_new = sp.csr_matrix((rb.m, rb.m_total), dtype=bool)
        rb.last_blocks = {}
        rb.stopped = True
        rb.t_stop = int(t_stop[i])
        rb.conflictive = conflictive_f[o0:o1].copy()
        rb.set_label = label_f[o0:o1].copy()
        named = named_f[o0:o1]
        rb.track_label[named] = smallest_f[o0:o1][named]
        ra, rb_ = rep_bounds[i], rep_bounds[i + 1]
        rb.root_of_set = dict(zip(smallest[reps[ra:rb_]].tolist(), root[ra:rb_].tolist(),
                                  strict=True))
    return n_sets


def _roots(reps: np.ndarray, starts: np.ndarray, counts: np.ndarray,
           cam: np.ndarray) -> np.ndarray:
    """Eq. (10) for each representative row: the robot with most features, ties lowest id."""
    if reps.size == 0:
        return _EMPTY
    c = counts[reps]
    srow = np.repeat(np.arange(reps.size), c)
    entry = np.repeat(starts[reps] - np.concatenate([[0], np.cumsum(c)[:-1]]), c) + \
        np.arange(int(c.sum()))
    scam = cam[entry]
    # features per (set, robot): m~_j of Def. 4.1, by run lengths (cams sorted within a row)
    start = np.flatnonzero(np.r_[True, (srow[1:] != srow[:-1]) | (scam[1:] != scam[:-1])])
    run_len = np.diff(np.r_[start, srow.size])
    run_set, run_cam = srow[start], scam[start]
    # per set (runs in camera order): the first run of the greatest length
    set_start = np.flatnonzero(np.r_[True, run_set[1:] != run_set[:-1]])
    best = np.maximum.reduceat(run_len, set_start)
    cand = np.flatnonzero(run_len == best[run_set])
    firsts = cand[np.r_[True, run_set[cand][1:] != run_set[cand][:-1]]]
    return run_cam[firsts]
