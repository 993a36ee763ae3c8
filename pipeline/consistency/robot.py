"""The robot agent of the distributed consistency stage (Aragüés et al., Secs. II–IV).

A :class:`Robot` holds only its own state: its id, its feature count, its association blocks
``W_ij`` with its neighbours, its detection blocks ``X_i·(t)``, the last blocks received from
each neighbour, its component assignments and a log of the links it deleted. Public
knowledge shared by all robots is the team size ``n`` and every robot's feature count (so
every robot can turn ``(j, s)`` into the global column ``offsets[j] + s``). A robot never
reads another robot or a global matrix: it acts on its inbox and sends through its
:class:`~pipeline.transport.Endpoint` of the transport. The algorithms themselves are in
:mod:`.detection` (Sec. III) and :mod:`.resolution` (Sec. IV, Alg. 1).

Storage of ``W_i·``: the blocks ``W_ij`` for all neighbours ``j`` are kept together as one
coordinate list of the non-zero entries (``link_nbr = j``, ``link_r = r``, ``link_s = s``,
``[W_ij]_{r,s} = 1``), sorted by ``(j, s)``, with a boolean ``link_alive`` that Alg. 1 lines 10
and 18 clear. ``W_ii = I`` (Assumption 2.1) is implicit. :meth:`Robot.block` returns ``W_ij``
as a sparse boolean matrix.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

__all__ = ["Robot", "csr_bytes", "blocks_bytes"]

# deletion log codes
CASE_B, CASE_C, ON_REJECT, ROBOT_LOST = 1, 2, 3, 4
CASE_NAMES = {CASE_B: "b", CASE_C: "c", ON_REJECT: "reject", ROBOT_LOST: "robot-lost"}


def csr_bytes(a: sp.csr_matrix) -> int:
    """Bytes of a CSR matrix as held: data + indices + indptr."""
    return int(a.data.nbytes + a.indices.nbytes + a.indptr.nbytes)


def blocks_bytes(blocks) -> int:
    """Bytes of received blocks ``(rows, csr block)``."""
    return sum(int(rows.nbytes) + csr_bytes(blk) for rows, blk in blocks)


class Robot:
    """One robot (= one camera) of the team.

    Parameters
    ----------
    robot_id : int
    features_per_camera : array_like, (n,) int
        Public feature counts of all robots (column offsets of ``X_i·``).
    link_nbr, link_r, link_s : array_like, (L_i,) int
        The robot's own associations: ``[W_{i, nbr}]_{r, s} = 1``.
    offsets : ndarray, (n + 1,) int64, optional
        The same public counts as read-only column offsets, shared by the robots of one team
        (``features_per_camera`` is then not read), with ``key_base`` the largest count + 1.

    Attributes
    ----------
    X : scipy.sparse.csr_matrix, (m_i, m_total) bool
        ``X_i·(t)``: row ``r`` holds the global ids of the features reachable from ``f_r^i``
        (Def. 3.4: kept boolean). Rows of features outside the current detection are empty.
    X_new : scipy.sparse.csr_matrix, (m_i, m_total) bool
        What the next ``blocks`` messages carry: the entries of ``X`` new in the last step
        (delta messages), or ``X`` itself (whole blocks).
    component : ndarray, (m_i,) int64
        Component ``C_q`` of each feature (``q`` = global id of the root feature), ``-1`` if
        unassigned.
    """

    def __init__(self, robot_id: int, features_per_camera, link_nbr, link_r, link_s,
                 offsets: np.ndarray | None = None, key_base: int | None = None) -> None:
        self.id = int(robot_id)
        if offsets is None:
            fpc = np.asarray(features_per_camera, dtype=np.int64)
            offsets = np.concatenate([[0], np.cumsum(fpc)]).astype(np.int64)
            offsets.flags.writeable = False
            key_base = int(fpc.max(initial=0)) + 1
        else:  # the team's public layout, one read-only array for all robots (memory
            # then follows the links, not cameras squared)
            if key_base is None:
                key_base = int(np.diff(offsets).max(initial=0)) + 1
        self.n = int(offsets.shape[0]) - 1
        self.offsets = offsets
        self.m = int(offsets[self.id + 1] - offsets[self.id])
        self.m_total = int(self.offsets[-1])
        nbr = np.asarray(link_nbr, dtype=np.int32)
        r = np.asarray(link_r, dtype=np.int32)
        s = np.asarray(link_s, dtype=np.int32)
        # key used to find the link (j, s) named by a neighbour's message
        self._key_base = key_base
        key = nbr.astype(np.int64) * self._key_base + s
        if key.size > 1 and not (key[1:] > key[:-1]).all():  # else already in (j, s) order
            order = np.lexsort((s, nbr))
            nbr, r, s, key = nbr[order], r[order], s[order], key[order]
        self.link_nbr, self.link_r, self.link_s = nbr, r, s
        self.link_alive = np.ones(key.shape[0], dtype=bool)
        self.link_key = key
        self.gid0 = int(self.offsets[self.id])

        # detection state (Sec. III)
        self.X = sp.csr_matrix((self.m, self.m_total), dtype=bool)
        self.X_new = self.X
        self.last_blocks: dict[int, tuple[np.ndarray, sp.csr_matrix]] = {}
        self.candidates = np.ones(self.m, dtype=bool)  # features (re)examined next detection
        self.active = np.zeros(self.m, dtype=bool)
        self.stopped = True
        self.t_stop = 0
        self.conflictive = np.zeros(self.m, dtype=bool)
        self.set_label = np.full(self.m, -1, dtype=np.int64)
        self.root_of_set: dict[int, int] = {}

        # the track of each own feature as learnt by detection (smallest global id of its
        # non-conflictive row), -1 until then; see final_tracks
        self.track_label = np.full(self.m, -1, dtype=np.int64)

        # resolution state (Sec. IV, Alg. 1)
        self.component = np.full(self.m, -1, dtype=np.int64)
        self.assigned_round = np.full(self.m, -1, dtype=np.int32)
        self.deleted_round = np.full(self.link_r.shape[0], -1, dtype=np.int32)
        self.deleted_case = np.zeros(self.link_r.shape[0], dtype=np.int8)
        self.deleted_iteration = np.full(self.link_r.shape[0], -1, dtype=np.int32)
        self.iteration = 0
        self.peak_memory_bytes = 0

    # --- views ----------------------------------------------------------------------------
    def block(self, j: int) -> sp.csr_matrix:
        """``W_ij`` as a sparse boolean ``(m_i, m_j)`` matrix (Assumption 2.1: ``W_ii = I``)."""
        mj = int(self.offsets[j + 1] - self.offsets[j])
        if j == self.id:
            return sp.identity(self.m, dtype=bool, format="csr")
        sel = (self.link_nbr == j) & self.link_alive
        return sp.csr_matrix((np.ones(int(sel.sum()), dtype=bool),
                              (self.link_r[sel], self.link_s[sel])), shape=(self.m, mj))

    def neighbours_with_links(self) -> np.ndarray:
        """Neighbours ``j`` with a non-zero ``W_ij`` (alive links only), sorted."""
        return np.unique(self.link_nbr[self.link_alive])

    def find_links(self, nbr: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Index in the link table of ``[W_{i,nbr}]_{·, s}``, ``-1`` where there is none."""
        key = np.asarray(nbr, dtype=np.int64) * self._key_base + np.asarray(s, dtype=np.int64)
        if self.link_key.size == 0:
            return np.full(key.shape, -1, dtype=np.int64)
        pos = np.minimum(np.searchsorted(self.link_key, key), self.link_key.size - 1)
        return np.where(self.link_key[pos] == key, pos, -1)

    # --- operations -----------------------------------------------------------------------
    def delete_links(self, links: np.ndarray, round_: int, case: int) -> None:
        """Delete the alive links among ``links`` (indices in the link table) and log why.

        ``case`` is one of ``CASE_B``, ``CASE_C`` (Alg. 1 line 10), ``ON_REJECT`` (line 18)
        or ``ROBOT_LOST``; a link already deleted keeps its first log entry.
        """
        fresh = links[self.link_alive[links]]
        self.link_alive[fresh] = False
        self.deleted_round[fresh] = round_
        self.deleted_case[fresh] = case
        self.deleted_iteration[fresh] = self.iteration

    def final_tracks(self) -> np.ndarray:
        """Track of each own feature from this robot's own knowledge, ``(m_i,)`` int64.

        A feature with an alive link belongs to a track (an association set of the kept links)
        named by the robot alone: the component ``q`` of Alg. 1 if the feature was assigned to
        one (a component keeps no link to the outside, Alg. 1 cases (b)–(c), so it is a whole
        set), else the smallest global id of its row ``X_i·`` in the detection that found it
        non-conflictive (Prop. 3.5: that row is its whole association set, and resolution
        never touches a set without conflict). Every robot of a track computes the same name.
        ``-1``: no alive link. Links cut after that detection for a lost robot (``robot-lost``)
        can split a set whose name stays shared.
        """
        has_link = np.zeros(self.m, dtype=bool)
        has_link[self.link_r[self.link_alive]] = True
        label = np.where(self.component >= 0, self.component, self.track_label)
        return np.where(has_link, label, -1)

    # --- memory ---------------------------------------------------------------------------
    def fixed_bytes(self) -> int:
        """Bytes of the arrays whose size does not change during a phase."""
        return sum(int(a.nbytes) for a in (
            self.link_nbr, self.link_r, self.link_s, self.link_alive, self.link_key,
            self.candidates, self.active, self.conflictive, self.set_label, self.component,
            self.track_label,
            self.assigned_round, self.deleted_round, self.deleted_case, self.deleted_iteration))

    def memory_bytes(self) -> int:
        """Bytes of the arrays this robot holds (sparse matrices: data + indices + indptr)."""
        total = self.fixed_bytes()
        total += csr_bytes(self.X) + blocks_bytes(self.last_blocks.values())
        if self.X_new is not self.X:
            total += csr_bytes(self.X_new)
        total += 16 * len(self.root_of_set)
        return total

    def measure_memory(self) -> int:
        """Update and return the peak of :meth:`memory_bytes`."""
        self.peak_memory_bytes = max(self.peak_memory_bytes, self.memory_bytes())
        return self.peak_memory_bytes
