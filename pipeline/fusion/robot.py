"""The fusion stage run by one robot alone over its end of the network (Montijano et al.).

:func:`pipeline.fusion.landmarks.fuse_tracks` evaluates every robot's update at once; here one
robot computes only its own rows of it, from its own state and its inbox, and sends what the
vectorized protocol counts (:mod:`pipeline.fusion.protocol`). With no fault the two agree bit
for bit: same local estimates, same draws, same consensus states, same cuts (tested).

What the robot knows
--------------------
Its own features' track names (:meth:`pipeline.consistency.robot.Robot.final_tracks`), its own
keypoints, pose and intrinsics, the team size ``n`` and the comm graph (public). Everything else
comes in messages from its comm-graph neighbours.

Logical rounds (each one :meth:`~pipeline.transport.RoundEndpoint.end_round`)
-----------------------------------------------------------------------------
1. **Setup** (``fusion-setup``, one message per neighbour): its camera (``R``, ``t`` and
   ``fx, fy, cx, cy``: 16 reals, the full ``K`` if it has skew) and, per track it observes,
   the track's name and its keypoint. A name it holds twice (a conflictive set, which the
   simulator leaves unfused) is sent apart, and every robot that hears it leaves the track out.
   From the setups the robot measures its keypoint noise ``σ_i``
   (:func:`pipeline.fusion.noise.robot_noise`, its own two-view residuals), forms its local
   estimate of each track (:func:`pipeline.fusion.local.local_estimates`, its own row) and its
   max-c draws (:func:`pipeline.fusion.protocol.hypothesis_draws`).
2. **Consensus**, in the mode of :func:`~pipeline.fusion.landmarks.fuse_tracks`
   (``FusionOptions.consensus``):

   * ``exact`` (default): the robot's :class:`pipeline.fusion.flood_robot.FloodRobot`, one
     :meth:`~pipeline.fusion.flood_robot.FloodRobot.step` per round, its messages on the wire in
     the layout that module counts (:func:`~pipeline.fusion.flood_wire.encode_flood`: the open tracks of a link are known
     at both ends, so they go unnamed; tombstones of lost links as that module counts them;
     once a robot has seen a lost link it names its open tracks, since tombstones can reopen
     a decision), until every track it observes is decided at the consensus limit
     (``Diam + 1`` rounds without faults);
   * ``metropolis``: steps 2a and 2b below.

2a. **Max-c consensus** (eq. 6, ``fusion-maxc``), ``n − 1`` rounds: per shared track a bit of a
   *changed* bitmap and the ``K c`` values of the changed ones; the members of eq. (7) follow.
2b. **Dynamic voting** (eqs. 10–14, ``fusion``), per-link delta messages and the distributed
   stop rule of :mod:`pipeline.fusion.protocol`: per running shared track its stop counter and
   a changed bit, per changed track the robot's degree in the track's observer graph (for the
   Metropolis weight) and its ``K`` bundles ``(P, q, v)`` (``P`` as its upper triangle: every
   ``P`` is exactly symmetric, :func:`pipeline.fusion.voting.information_matrix`). A track
   ends for the robot when its counter reaches ``W + 1`` (``W = n − 1``), or at the round cap.
   The update ``P_i(t + 1) = Σ_j a_ij P_j(t) + u_i Λ_i⁻¹`` sums its terms in the order of
   neighbour ids (the simulator's sparse row order), and ``a_ii`` subtracts the weights in the
   order of the comm edges (the simulator's), so the floats are the same.
3. **Decision**: the winner (``argmax_h v_i^h``; exact mode: the decision of the flood) and the
   outlier test of
   :func:`~pipeline.fusion.landmarks.fuse_tracks` (voted out, and its own keypoint does not
   reproject onto the fused landmark within the pixel gate). The robot tells each neighbour
   which of its features it declared outliers (``fusion-cut``, only when there are some); each
   end then cuts a link whose ends are one outlier and one not (an outlier leaves its
   landmark, a link of two outliers stays where the two can be one point:
   :mod:`pipeline.fusion.landmarks`, "Outliers leave
   the landmark"), both ends deciding alike.

Termination
-----------
The phase ends by the termination wave of :mod:`pipeline.consistency.termination`: a robot is
*done* once every track it observes has stopped and its ``fusion-cut`` messages left; done is
stable (nothing can restart a stopped track), so when the wave ends every robot has decided and
every cut has arrived. The wave also floods the largest round count (exact mode: the last
round in which the robot sent a flood message; Metropolis: max-c rounds plus its own consensus
rounds), which names the round of the fusion cuts as the simulator does.

Faults
------
A neighbour the transport reports silent (its process died) leaves every track's observer graph
at once. Exact mode: it is handed to :meth:`~pipeline.fusion.flood_robot.FloodRobot.step` as lost
(its entry counts as known-gone, so the robot's ball can close without it). Metropolis: its
terms leave the update (the robot's own weight takes them, so its row still sums to
one and the weights stay symmetric: both ends of a link use the degrees their messages of that
round carried), its degree changes are sent with the next round, and the robot cuts every link
to it as ``robot-lost``. On a lossy network every logical round goes over the reliable
channel in lockstep (:func:`~pipeline.fusion.robot_loops.run_fusion_reliably`), so the computation is the fault-free one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.fusion.consensus import ransac_hypotheses, solve_information, top_c_distinct
from pipeline.fusion.flood_wire import TRIU, decode_flood, encode_flood
from pipeline.fusion.local import (
    local_estimates,
    observing_neighbours,
    outlier_pair_tol,
    pair_agrees,
    project,
    two_view_points,
)
from pipeline.fusion.noise import robot_noise
from pipeline.fusion.protocol import (
    bundle_reals,
    hypothesis_draws,
    index_bytes,
    to_wire,
)
from pipeline.fusion.voting import (
    VOTE_TIE_TOL,
    chi2_ppf,
    gate_threshold,
    information_matrix,
    sq_mahalanobis,
    winning_view,
)

__all__ = ["FusionOptions", "FusionRobot", "SETUP", "MAXC", "FUSION", "FLOOD", "CUT",
           "CUT_DTYPE"]

SETUP, MAXC, FUSION, CUT = "fusion-setup", "fusion-maxc", "fusion", "fusion-cut"
#: the feature ids of a ``fusion-cut`` message (what the simulator counts for it too)
CUT_DTYPE = np.int32
FLOOD = FUSION  # the simulator counts the flood as the consensus: kind "fusion"
_BIG = np.iinfo(np.int64).max // 2


@dataclass
class FusionOptions:
    """The options of :func:`pipeline.fusion.landmarks.fuse_tracks` a robot runs with (its
    defaults, the stage's)."""

    sigma_px: float = 1.0
    local: str = "robust"
    p: float = 0.99
    gate: str = "squared"
    p_in: float = 0.7
    c: int = 1
    success: float = 0.99
    rounds: int = 100
    seed: int = 0
    wire: str = "float32"
    consensus: str = "exact"
    noise: str = "measured"


def _camera_payload(K, R, t) -> np.ndarray:
    K = np.asarray(K, np.float64)
    cam = [np.asarray(R, np.float64).reshape(9), np.asarray(t, np.float64).reshape(3)]
    if K[0, 1] == 0 and K[1, 0] == 0 and (K[2] == [0, 0, 1]).all():
        cam.append(np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2]]))
    else:
        cam.append(K.reshape(9))
    return np.concatenate(cam)


def _camera_from(cam: np.ndarray):
    R, t = cam[:9].reshape(3, 3), cam[9:12]
    if len(cam) == 16:
        fx, fy, cx, cy = cam[12:]
        K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    else:
        K = cam[12:21].reshape(3, 3)
    return K, R, t


class FusionRobot:
    """Robot ``i``'s fusion: its own state, what it sends each round, what it does with its
    inbox (module docstring).

    Parameters
    ----------
    i : int — its id
    n : int — team size (public)
    comm_edges : array_like, (E, 2) int — the comm graph, in the team's order (public)
    track_names : ndarray, (m_i,) int — its own name for the track of each of its features,
        ``-1`` outside tracks
    keypoints : ndarray, (m_i, 2) float32
    K, R, t : its intrinsics and pose (``cam_from_world``)
    options : FusionOptions or None
    """

    def __init__(self, i: int, n: int, comm_edges, track_names, keypoints, K, R, t,
                 options: FusionOptions | None = None) -> None:
        self.i, self.n = int(i), int(n)
        self.opt = options or FusionOptions()
        comm = np.asarray(comm_edges, dtype=np.int64).reshape(-1, 2)
        self.neighbours = sorted({int(b) for a, b in comm if a == self.i}
                                 | {int(a) for a, b in comm if b == self.i})
        # a node's edges are ordered like the comm edges: first those where it is the first end
        self._first = [int(b) for a, b in comm if a == self.i]
        self._second = [int(a) for a, b in comm if b == self.i]
        self.alive = set(self.neighbours)
        # the Metropolis mode keeps what it hears from neighbour j in column col[j]
        self.col = {j: c for c, j in enumerate(self.neighbours)}
        lab = np.asarray(track_names, dtype=np.int64).reshape(-1)
        self.track_of = lab   # its own name for the track of each of its features
        have = np.flatnonzero(lab >= 0)
        names, inv, counts = np.unique(lab[have], return_inverse=True, return_counts=True)
        single = counts[inv] == 1
        self.names = names[counts == 1]
        self.feat = np.empty(len(self.names), dtype=np.int64)
        self.feat[np.searchsorted(self.names, lab[have[single]])] = have[single]
        self.conflictive = names[counts > 1]
        self.keypoints = np.asarray(keypoints, dtype=np.float32).reshape(-1, 2)
        self.K = np.asarray(K, np.float64)
        self.R = np.asarray(R, np.float64)
        self.t = np.asarray(t, np.float64).reshape(3)
        self.px_thr = chi2_ppf(self.opt.p, 2)
        self.sigma, self.noise_residuals = float(self.opt.sigma_px), 0  # measured in the setup
        self.thr = gate_threshold(3, self.opt.p, self.opt.gate)
        self.Kh = ransac_hypotheses(self.opt.p_in, self.opt.c, self.opt.success)
        self.W = self.n - 1
        self.setups: dict[int, dict] = {}
        self.phase = "setup"
        self.maxc_round = 0
        self.round = 0            # consensus round
        self.local_rounds = 0     # max-c rounds + consensus rounds until all own tracks stopped
        self.outlier_feats = np.zeros(0, dtype=np.int64)
        self.cuts_from: dict[int, np.ndarray] = {}
        self.lost: list[int] = []
        self.counts = {"messages": 0, "bytes": 0}

    # --- round 1: setup -------------------------------------------------------------------
    def setup_messages(self) -> list[tuple[int, str, dict]]:
        payload = {"names": self.names.astype(np.int64),
                   "keypoints": self.keypoints[self.feat].astype(np.float32),
                   "camera": _camera_payload(self.K, self.R, self.t),
                   "conflictive": self.conflictive.astype(np.int64)}
        return [(j, SETUP, payload) for j in self.neighbours if j in self.alive]

    def _prepare(self) -> None:
        """Local estimates, draws and the consensus state, once the setups are in."""
        n, i = self.n, self.i
        drop = set(int(x) for x in self.conflictive)
        for s in self.setups.values():
            drop |= set(int(x) for x in s["conflictive"])
            u, c = np.unique(s["names"], return_counts=True)
            drop |= set(int(x) for x in u[c > 1])
        keep = ~np.isin(self.names, sorted(drop))
        self.names, self.feat = self.names[keep], self.feat[keep]
        B = len(self.names)
        # the robot's view of the team: itself and the neighbours whose setups came, in robot
        # order (column v is robot view[v]); its estimates use no other robot, and the order
        # keeps every sum and tie-break of the team-wide tables
        view = np.array(sorted({i} | set(self.setups)), dtype=np.int64)
        L, li = len(view), int(np.searchsorted(view, i))
        observes = np.zeros((B, L), dtype=bool)
        observes[:, li] = True
        kp = np.zeros((B, L, 2))
        kp[:, li] = self.keypoints[self.feat].astype(np.float64)
        Rs = np.broadcast_to(np.eye(3), (L, 3, 3)).copy()
        ts = np.zeros((L, 3))
        Ks = Rs.copy()
        Ks[li], Rs[li], ts[li] = self.K, self.R, self.t
        adj = np.zeros((L, L), dtype=bool)
        for j, s in self.setups.items():
            v = int(np.searchsorted(view, j))
            Ks[v], Rs[v], ts[v] = _camera_from(s["camera"])
            adj[li, v] = adj[v, li] = True
            pos = np.searchsorted(self.names, s["names"])
            ok = (pos < B) & (self.names[np.minimum(pos, max(B - 1, 0))] == s["names"]) \
                if B else np.zeros(len(s["names"]), bool)
            observes[pos[ok], v] = True
            kp[pos[ok], v] = s["keypoints"][ok].astype(np.float64)
        own = np.zeros(L, dtype=bool)
        own[li] = True
        # its own keypoint noise (the scale of its Λ_i, its vote and its pixel check), from
        # the two-view points its robust local estimate is built from
        pairs = two_view_points(kp, observing_neighbours(observes, adj, own), Rs, ts, Ks) \
            if self.opt.noise == "measured" and self.opt.local == "robust" else None
        sigma, residuals = robot_noise(kp, observes, adj, Rs, ts, Ks, self.opt.sigma_px,
                                       self.opt.p, self.opt.noise, robots=own, pairs=pairs)
        self.sigma, self.noise_residuals = float(sigma[li]), int(residuals[li])
        X, cov, est = local_estimates(kp, observes, adj, Rs, ts, Ks, sigma,
                                      self.px_thr, self.opt.local, robots=own, pairs=pairs)
        self.kp_own = kp[:, li]
        self.est = est[:, li]
        # the voting inputs as dynamic_voting prepares them (pipeline.fusion.voting._prepare)
        self.x = np.where(self.est[:, None], X[:, li], 0.0)
        cov_i = np.where(self.est[:, None, None], cov[:, li], np.eye(3))
        self._cov_i = cov_i
        self.nb_obs = np.zeros((B, n), dtype=bool)     # (B, n): observing neighbours per track
        self.nb_obs[:, view] = observes & adj[li][None]
        self.nb_obs[:, i] = False
        self.shared = {j: np.flatnonzero(self.nb_obs[:, j]) for j in self.neighbours}
        Kh, c = self.Kh, self.opt.c
        draws = hypothesis_draws(self.opt.seed, self.names, np.full(B, i), Kh)
        draws[~self.est] = -np.inf
        self.draws = draws
        self.sets = np.full((B, Kh, c), -np.inf)
        self.sets[:, :, 0] = draws
        self.nb_sets = np.full((B, len(self.neighbours), Kh, c), -np.inf)
        self.maxc_changed = np.ones(B, dtype=bool)
        # consensus state (pipeline.fusion.voting._dynamic_voting_protocol, this robot's rows)
        self.info = information_matrix(cov_i).reshape(B, 1, 3, 3)
        self.xf = self.x.reshape(B, 1, 3)
        self.u_P = self.info
        self.u_q = (self.info @ self.xf[..., None])[..., 0]
        self.B = B

    # --- rounds ---------------------------------------------------------------------------
    def messages(self) -> list[tuple[int, str, dict]]:
        """What this robot sends in the current round: ``(neighbour, kind, payload)``."""
        if self.phase == "setup":
            return self.setup_messages()
        if self.phase == "flood":
            return self._flood_messages()
        if self.phase == "maxc":
            return self._maxc_messages()
        if self.phase == "consensus":
            return self._consensus_messages()
        if self.phase == "cut":
            return self._cut_messages()
        return []

    def receive(self, inbox, lost=()) -> None:
        """Take in the inbox of the round just closed (``lost``: neighbours silent from now on)."""
        for k in lost:
            self._lose(int(k))
        for msg in inbox:
            if msg.src not in self.alive:
                continue
            if msg.kind == CUT:
                self.cuts_from[msg.src] = np.concatenate(
                    [self.cuts_from.get(msg.src, np.zeros(0, np.int64)),
                     msg.payload["feat"].astype(np.int64)])
        if self.phase == "setup":
            for msg in inbox:
                if msg.kind == SETUP and msg.src in self.alive:
                    self.setups[msg.src] = msg.payload
            self._prepare()
            if self.opt.consensus == "exact":
                self._start_flood()
                return
            self.phase = "maxc" if self.n > 1 else "consensus"
            if self.phase == "consensus":
                self._start_consensus()
        elif self.phase == "flood":
            self._flood_receive(inbox)
        elif self.phase == "maxc":
            self._maxc_receive(inbox)
        elif self.phase == "consensus":
            self._consensus_receive(inbox)
        elif self.phase == "cut":
            self.phase = "done"

    @property
    def done(self) -> bool:
        return self.phase == "done"

    def _lose(self, k: int) -> None:
        if k not in self.alive:
            return
        self.alive.discard(k)
        self.lost.append(k)
        if hasattr(self, "nb_obs"):
            self.nb_obs[:, k] = False

    # --- max-c consensus (eq. 6) ----------------------------------------------------------
    def _maxc_messages(self):
        out = []
        for j in self.neighbours:
            S = self.shared[j]
            if j not in self.alive or not len(S):
                continue
            ch = self.maxc_changed[S]
            out.append((j, MAXC, {"changed": np.packbits(ch), "sets": self.sets[S[ch]]}))
        return out

    def _maxc_receive(self, inbox) -> None:
        for msg in inbox:
            if msg.kind != MAXC or msg.src not in self.alive:
                continue
            S = self.shared[msg.src]
            ch = np.unpackbits(msg.payload["changed"], count=len(S)).astype(bool)
            self.nb_sets[S[ch], self.col[msg.src]] = msg.payload["sets"]
        B, Kh, c = self.sets.shape
        nb = np.where(self.nb_obs[:, self.neighbours, None, None], self.nb_sets, -np.inf)
        cand = np.concatenate([self.sets[:, None], nb], axis=1)            # (B, 1+deg, K, c)
        # (the width spelt out: a robot that observes no track has B = 0, where -1 is undefined)
        new_sets = top_c_distinct(cand.transpose(0, 2, 1, 3).reshape(B, Kh, cand.shape[1] * c), c)
        self.maxc_changed = (new_sets != self.sets).any(axis=(1, 2))
        self.sets = new_sets
        self.maxc_round += 1
        if self.maxc_round >= self.n - 1:
            self._start_consensus()

    # --- dynamic voting (eqs. 10-14) with the stop rule ------------------------------------
    def _start_consensus(self) -> None:
        B, Kh = self.B, self.Kh
        wire = self.opt.wire
        self.members = np.isfinite(self.draws) & (self.sets == self.draws[..., None]).any(-1)
        m = self.members.astype(np.float64)
        self.P = to_wire(self.u_P * m[..., None, None], wire)                # eq. (5)
        self.q = to_wire(self.u_q * m[..., None], wire)
        self.v = m.copy()                                                    # eq. (10)
        self.prev_yes = self.members.copy()
        self.stopped = np.zeros(B, dtype=bool)
        self.counter = np.zeros(B, dtype=np.int64)
        self.sent = None
        self.deg = self.nb_obs.sum(1)
        self.deg_changed = np.zeros(B, dtype=bool)
        self.theta = np.zeros((B, Kh, 3))
        self.ok = np.zeros((B, Kh), dtype=bool)
        self.yes = self.prev_yes.copy()
        m = len(self.neighbours)   # column col[j]: neighbour j
        self.nb_P = np.zeros((B, m, Kh, 3, 3))
        self.nb_q = np.zeros((B, m, Kh, 3))
        self.nb_v = np.zeros((B, m, Kh))
        self.nb_deg = np.zeros((B, m), dtype=np.int64)
        self.nb_counter = np.zeros((B, m), dtype=np.int64)
        self.nb_stopped = np.zeros((B, m), dtype=bool)
        self.counter_dtype = np.dtype(f"u{index_bytes(self.W + 1)}")
        self.deg_dtype = np.dtype(f"u{index_bytes(self.n)}")
        self.wire_dtype = np.float32 if wire == "float32" else np.float64
        self.changed_bytes = (index_bytes(self.n) + bundle_reals(Kh, 3)
                              * np.dtype(self.wire_dtype).itemsize)
        self.phase = "consensus"
        self.round = 0
        if B == 0:
            self._finish()

    def _opinion(self, run) -> None:
        th, okr = solve_information(self.P[run], self.q[run])            # θ_i = P_i⁻¹ q_i
        self.theta[run], self.ok[run] = th, okr
        obs_f = self.est.reshape(-1, 1)
        self.yes[run] = okr & obs_f[run] & (
            sq_mahalanobis(self.xf[run] - th, self.info[run]) <= self.thr)   # eq. (12)

    def _consensus_messages(self):
        wire = self.opt.wire
        run = ~self.stopped
        self.run = run
        self._opinion(run)
        u = self.yes.astype(np.float64) - self.prev_yes                    # eqs. (13)-(14)
        self.prev_yes = self.yes.copy()
        image = (to_wire(self.P, wire), to_wire(self.q, wire), to_wire(self.v, wire))
        changed = np.ones(self.B, dtype=bool) if self.sent is None else self.deg_changed.copy()
        if self.sent is not None:
            for now_, before in zip(image, self.sent, strict=True):
                changed |= (now_ != before).reshape(self.B, -1).any(1)
        self.sent = image
        self.image, self.u = image, u
        # the stop rule's counters (pipeline.fusion.protocol.stop_counters, this robot's rows)
        flag = ~changed & (u == 0).all(1)
        prev = np.where(self.stopped, _BIG, self.counter)
        nbc = np.where(self.nb_obs[:, self.neighbours] & ~self.nb_stopped, self.nb_counter,
                       _BIG).min(1, initial=_BIG)
        self.counter = np.where(flag, 1 + np.minimum(prev, nbc), 0)
        self.stopping = run & (self.counter >= self.W + 1)
        self.deg_sent = self.deg.copy()
        out = []
        for j in self.neighbours:
            S = self.shared[j]
            if j not in self.alive or not len(S):
                continue
            R = S[run[S]]
            if not len(R):
                continue
            ch = changed[R]
            C = R[ch]
            out.append((j, FUSION, {
                "c": self.counter[R].astype(self.counter_dtype),
                "changed": np.packbits(ch),
                "deg": self.deg[C].astype(self.deg_dtype),
                "P": image[0][C][..., TRIU[0], TRIU[1]].astype(self.wire_dtype),
                "q": image[1][C].astype(self.wire_dtype),
                "v": image[2][C].astype(self.wire_dtype)}))
        return out

    def _consensus_receive(self, inbox) -> None:
        wire = self.opt.wire
        Kh = self.Kh
        for msg in inbox:
            if msg.kind != FUSION or msg.src not in self.alive:
                continue
            j, p = self.col[msg.src], msg.payload
            S = self.shared[msg.src]
            R = S[~self.nb_stopped[S, j]]
            ch = np.unpackbits(p["changed"], count=len(R)).astype(bool)
            C = R[ch]
            self.nb_counter[R, j] = p["c"].astype(np.int64)
            self.nb_deg[C, j] = p["deg"].astype(np.int64)
            Pm = np.zeros((len(C), Kh, 3, 3))
            Pm[..., TRIU[0], TRIU[1]] = p["P"].astype(np.float64)
            Pm[..., TRIU[1], TRIU[0]] = p["P"].astype(np.float64)
            self.nb_P[C, j] = Pm
            self.nb_q[C, j] = p["q"].astype(np.float64)
            self.nb_v[C, j] = p["v"].astype(np.float64)
            self.nb_stopped[R[self.nb_counter[R, j] >= self.W + 1], j] = True
        self.stopped |= self.stopping
        self.round += 1
        new_deg = self.nb_obs.sum(1)
        self.deg_changed = new_deg != self.deg
        self.deg = new_deg
        if self.stopped.all():
            self._finish()
            return
        run = ~self.stopped
        P, q, v = self._mix()
        u = self.u
        Pn = P + u[..., None, None] * self.u_P                               # eq. (11)
        qn = q + u[..., None] * self.u_q
        vn = v + u
        self.P[run], self.q[run], self.v[run] = (to_wire(a[run], wire) for a in (Pn, qn, vn))
        if self.round >= self.opt.rounds:                                   # the cap
            self._finish()

    def _mix(self):
        """``Σ_j a_ij X_j(t)`` over the images of the round: Metropolis weights from the degrees
        this round's messages carried, terms in neighbour-id order (the simulator's sparse row
        order), ``a_ii`` with the weights subtracted in comm-edge order (its ``bincount``)."""
        i, col = self.i, self.col
        contrib = self.nb_obs[:, self.neighbours]                           # alive neighbours
        w = np.where(contrib, 1.0 / (1.0 + np.maximum(self.deg_sent[:, None], self.nb_deg)), 0.0)
        s1 = np.zeros(self.B)
        for j in self._first:
            s1 = s1 + np.where(contrib[:, col[j]], w[:, col[j]], 0.0)
        s2 = np.zeros(self.B)
        for j in self._second:
            s2 = s2 + np.where(contrib[:, col[j]], w[:, col[j]], 0.0)
        diag = 1.0 - s1 - s2
        P = np.zeros_like(self.P)
        q = np.zeros_like(self.q)
        v = np.zeros_like(self.v)
        img = self.image
        for j in sorted({i} | self.alive):                                   # robot order
            if j == i:
                a = diag
                Pj, qj, vj = img
                sel = np.ones(self.B, dtype=bool)
            else:
                c = col[j]
                a = w[:, c]
                Pj, qj, vj = self.nb_P[:, c], self.nb_q[:, c], self.nb_v[:, c]
                sel = contrib[:, c]
            P = P + np.where(sel[:, None, None, None], a[:, None, None, None] * Pj, 0.0)
            q = q + np.where(sel[:, None, None], a[:, None, None] * qj, 0.0)
            v = v + np.where(sel[:, None], a[:, None] * vj, 0.0)
        return P, q, v

    def _finish(self) -> None:
        """Decisions on every own track (:func:`~pipeline.fusion.landmarks.fuse_tracks`)."""
        B = self.B
        if B:
            run = ~self.stopped
            if run.any():                                                   # the cap was reached
                self._opinion(run)
            # the simulator's rule with the stop rule on (fuse_tracks: ties within VOTE_TIE_TOL)
            self.winner, self.theta_w, self.ok_w, self.yes_w = winning_view(
                self.theta, self.ok, self.yes, self.v, VOTE_TIE_TOL)
            self._outliers()
        else:
            self.winner = np.zeros(0, np.int64)
            self.theta_w = np.zeros((0, 3))
            self.ok_w = self.yes_w = self.outlier = np.zeros(0, bool)
        self.local_rounds = (self.n - 1 if self.n > 1 else 0) + (self.round if B else 0)
        self.phase = "cut"

    def _outliers(self) -> None:
        """The outlier test of :func:`~pipeline.fusion.landmarks.fuse_tracks` on the decided
        ``θ``, validity and own vote of every own track."""
        if self.B:
            voted_out = self.est & ~self.yes_w
            u, _, z = project(self.theta_w[:, None], self.R[None, None], self.t[None, None],
                               self.K[None, None])
            e2 = ((u[:, 0] - self.kp_own) ** 2).sum(-1) / self.sigma ** 2
            reproj_ok = self.ok_w & (z[:, 0] > 0) & (e2 <= self.px_thr)
            self.outlier = voted_out & self.ok_w & ~reproj_ok
        else:
            self.outlier = np.zeros(0, bool)
        self.outlier_feats = self.feat[self.outlier]

    # --- the exact consensus (pipeline.fusion.flooding) ------------------------------------
    def _start_flood(self) -> None:
        """Exact consensus: the robot's FloodRobot over its own tracks (after the setup)."""
        from pipeline.fusion.flood_robot import FloodRobot

        cov_i = self._cov_i
        info = information_matrix(cov_i)
        tracks = {int(b): dict(neighbours=self.nb_obs[k].copy(), estimated=bool(self.est[k]),
                               draws=self.draws[k], x=self.x[k], info=info[k])
                  for k, b in enumerate(self.names)}
        self.flood = FloodRobot(self.i, self.n, tracks, K=self.Kh, d=3, wire=self.opt.wire,
                                c=self.opt.c, thr=self.thr)
        self.saw_tombstone = False
        self.last_sent: dict = {}      # (track, neighbour) -> round of this robot's last to it
        self.closed_from: set = set()  # (track, neighbour) whose last this robot received
        self.flood_out = self.flood.step([], ())
        self.flood_last_send = 1 if self.flood_out else 0
        self.phase = "flood"


    def _flood_messages(self):
        named = bool(self.lost) or self.saw_tombstone
        out = []
        for m in self.flood_out:
            if m.dst not in self.alive:
                continue
            for b in m.names[m.last].tolist():
                self.last_sent.setdefault((b, m.dst), self.flood.round)
            out.append((m.dst, FLOOD, encode_flood(m, self.n, self.opt.wire,
                                                   self._shared_names(m.dst), named)))
        return out

    def _shared_names(self, j: int) -> list:
        return [int(self.names[k]) for k in self.shared.get(j, ())]


    def _flood_receive(self, inbox) -> None:
        if self.flood.finished:
            self._finish_flood()
            return
        msgs = [decode_flood(m.src, self.i, self.flood.round, self._open_tracks(m.src),
                             m.payload, self.n, self.Kh, self._shared_names(m.src))
                for m in inbox if m.kind == FLOOD and m.src in self.alive]
        self.saw_tombstone |= any(m.down for m in msgs)
        for m in msgs:
            for b in m.names[m.last].tolist():
                self.closed_from.add((b, m.src))
        self.flood_out = self.flood.step(msgs, sorted(set(self.lost)))
        if self.flood_out:
            self.flood_last_send = self.flood.round


    def _open_tracks(self, j: int) -> list:
        """Names of the tracks neighbour ``j``'s message of this round carries when it does not
        name them (it has seen no lost link, so it follows the fault-free rule): the shared
        tracks whose last ``j`` has not sent, unless this robot's own last for the track
        reached ``j`` before this round (``j`` sends a track until it holds that last)."""
        t = self.flood.round
        return [b for b in self._shared_names(j) if (b, j) not in self.closed_from
                and not self.last_sent.get((b, j), t) < t]

    def _finish_flood(self) -> None:
        B, i = self.B, self.i
        dec = [self.flood.decisions[int(b)] for b in self.names]
        self.winner = np.array([int(d.winner) for d in dec], dtype=np.int64)
        self.theta_w = np.array([d.theta for d in dec], dtype=np.float64).reshape(B, 3)
        self.ok_w = np.array([bool(d.valid) for d in dec], dtype=bool)
        self.yes_w = np.array([bool(d.yes[d.winner, i]) and bool(d.valid) for d in dec], dtype=bool)
        self._outliers()
        self.local_rounds = int(self.flood_last_send)
        self.phase = "cut"

    # --- the decision's cuts ----------------------------------------------------------------
    def _cut_messages(self):
        if not len(self.outlier_feats):
            return []
        return [(j, CUT, {"feat": self.outlier_feats.astype(CUT_DTYPE)})
                for j in self.neighbours if j in self.alive]

    def cut_rows(self, link_nbr, link_r, link_s) -> np.ndarray:
        """Rows of the robot's link table cut by the fusion stage, ``(L_i,)`` bool: those whose
        ends are one outlier and one not (its own outlier features, its neighbours' as they
        told it; :mod:`pipeline.fusion.landmarks`, "Outliers leave the landmark")."""
        own = np.isin(link_r, self.outlier_feats)
        theirs = np.zeros(len(own), dtype=bool)
        for j, feats in self.cuts_from.items():
            theirs |= (link_nbr == j) & np.isin(link_s, feats)
        cut = own ^ theirs
        for k in np.flatnonzero(own & theirs):   # two outliers: stay if they can be one point
            cut[k] = not self._pair_agrees(int(link_nbr[k]), int(link_r[k]))
        return cut

    def _pair_agrees(self, j: int, f: int) -> bool:
        """:func:`~pipeline.fusion.local.pair_agrees` of its feature ``f`` and neighbour ``j``'s
        observation of the same track (its setup message: keypoint and camera), the lower id
        first, at :func:`~pipeline.fusion.local.outlier_pair_tol`: what ``j`` computes."""
        s = self.setups[j]
        at = np.flatnonzero(s["names"] == self.track_of[f])
        if not len(at):   # not a track it fused with j: nothing says they are one point
            return False
        mine = (self.keypoints[f].astype(np.float64), self.K, self.R, self.t)
        K, R, t = _camera_from(s["camera"])
        other = (s["keypoints"][at[0]].astype(np.float64), K, R, t)
        lo, hi = (mine, other) if self.i < j else (other, mine)
        uv, Ks, Rs, ts = (np.stack([lo[x], hi[x]])[None] for x in range(4))
        return bool(pair_agrees(uv, Rs, ts, Ks, outlier_pair_tol(self.opt.sigma_px,
                                                                   self.px_thr))[0])


# --------------------------------------------------------------------------------------------
# the exact consensus (pipeline.fusion.flooding): the robot's FloodRobot on the wire


