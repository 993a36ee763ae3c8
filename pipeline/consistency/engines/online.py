"""Online association: frames arrive step by step and the kept association stays conflict-free.

The papers take one snapshot (all images, one association). Here a team in motion adds one
frame per robot per step; :class:`OnlineAssociation` keeps every link ever made (kept or
cut, with the step that made and the step that cut it) and runs the distributed stage of
Aragüés et al. only on what the step's new links touch.

Words
-----
*Image* (a camera of the papers, Def. 2.4): one frame of one robot; a conflict is two
features of one image in one association set. *Window*: the stage holds the frames of a
robot's last ``W + H`` steps (``window`` ``W``, ``hold`` ``H``); at step ``t`` the frames of
steps ``t - W - H + 1 .. t`` are in the window, older frames are *retired*: their features
and the links between two retired frames are final. New links must join a frame of step
``t`` to a frame of the *matching window*, steps ``t - W + 1 .. t`` (the runner matches a new
frame against its robot's ``W - 1`` previous frames and its current neighbours' last ``W``
frames); the frames of the ``H`` steps before it are *held*: they take no new link, but they
are window frames of the stage in every other respect (their links stay open: the rule and
the repair may still cut them). A *retired piece* is a connected component of the
kept links between retired features; a *border link* is a kept link from a window feature
into a retired piece. A set of the association is exactly a component of the window's kept
links, the border links and the retired pieces (a piece is connected, so are the window
features its border links reach). *Label*: every window feature carries a name of its set
(a new feature starts as its own global id, every set a step's stage ran on gets a fresh
name, :data:`FRESH_LABELS`); a label always contains the whole set of its features (a later
cut, e.g. by fusion, may leave it naming several sets, which only widens the next check).

*Hold* (``hold``, default ``W - 1``: :func:`default_hold`). A link made at step ``s`` joins
frames of steps ``s - W + 1 .. s``; with ``H = 0`` it is final from step ``s + W`` on. The
frames matched with its frames (steps up to ``s + W - 1``) take new links until step
``s + 2W - 2``: a clash that reaches the link through one of them (two hops in time) may show
only once it is final, and the history repair must then cut an open link instead, often a
good one. (``bench/online_cuts.py``, a 6-robot, 20-step formation, seed 0, ``H = 0``: 623
history cuts, 435 of them good links, 382 of these in conflictive sets that held a spurious
link between two retired frames; with ``H = 2``: 51 history cuts, 15 good.) ``H = W - 1`` keeps the link open until step ``s + 2W - 2``, the last
step a two-hop clash arrives at; ``H = 0`` is the earlier rule. What a robot then holds: the
labels, links and border links of its last ``W + H`` frames and the retired entries below;
memory follows window + hold, not the history.

*Retired entries* summarize a piece for the history check: for each robot with retired
frames in the piece, the runs of consecutive steps of those frames, ``(piece, lo, hi)``, held
by that robot (one frame per robot per step, so a run names the frames exactly); beyond
:data:`RUNS_PER_ROBOT` runs the oldest runs of one robot merge into one run over their span
(a superset of its frames). A piece keeps its entries while a border link reaches it; a
piece no window feature reaches can never meet a new link, and its entries are dropped. So a
robot's entries are at most ``RUNS_PER_ROBOT`` per live piece it has frames in, and the live
pieces are reached by border links of window features: memory follows the window, not the
history (a track seen for a long time costs ``RUNS_PER_ROBOT`` entries per robot, not one per
frame).

One step (:meth:`OnlineAssociation.add_step`)
---------------------------------------------
1. The step's frames join the window, frames older than ``W + H`` steps retire: their tracked
   features join the retired pieces their kept links reach (pieces that meet merge and keep
   the smallest name; the robot of a retiring feature sends the piece's name over each link
   that becomes a border link, 8 bytes, and a renamed piece's entries learn the new name, 8
   bytes each: ``retire_bytes``).
2. *Incremental detection.* The touched labels are the labels of the new links' ends (each
   robot knows them: the two robots of a new link exchange their ends' labels, counted as
   one message of 16 bytes per link). The stage runs on the *sub-problem*: the window
   features of the touched labels (the step's new features included), the kept window links
   among them, the new links, and the *history links*: for every retired piece, a chain
   through the window features its border links reach (the set closes through the piece;
   the history link carries that connection, so the detection sees the set whole). On it
   the simulator runs the rule of :mod:`pipeline.consistency.rules` (default
   :data:`~pipeline.consistency.rules.DEFAULT_RESOLUTION`), images as its cameras, until
   conflict-free: a rule with Aragüés et al.'s detection (Sec. III, Prop. 3.5) loops
   detection and resolution (Prop. 4.5); the evidence rule is a whole stage (its bounded
   label flooding, the bundles of its sets of at most ``B`` features, the ``sync`` merge of
   the larger ones: :mod:`pipeline.consistency.engines.evidence_stage`), except that by
   default (``gather``) its conflictive sets of at most ``B`` features are solved as in
   step 2b, their bundles gathered at the set's root rather than flooded to every robot of
   the set (the same bundles and :func:`~pipeline.consistency.evidence.solve_set`, so the
   same cuts; the flood crosses every link of the set, the gathering one path per bundle:
   on a 20-robot formation the flood was about 95 % of a step's bytes,
   ``bench/online.py --no-gather``); a cut of a history link is
   ignored (it is no link of the association; a history link that doubles a real link is
   left to the real link in the detection and kept in the check below).
2b. *Weighing the conflict-free sets* (``weigh``, default; the evidence rule,
   :data:`WEIGHED_RULE`). The rule cuts only in the sets it finds conflictive (its sets of
   at most ``B`` features, the bundle budget; a larger set gets its ``sync`` merge, and is
   left to it here); every other set of the sub-problem, one the step's new links touched
   and found conflict-free, is weighed by the rule's merge too. Its robots send their
   bundles as the rule's robots make them (each window feature's keypoint, its links of
   the set with their evidence weights, its frame's projection; history links as in the
   rule's pass) up a tree to the set's *root*, the robot of the member that
   :func:`.roots.root_of` picks from the set list every robot of a set of at most ``B``
   features holds (a fixed scrambling of the ids, so a step's roots spread over its
   robots); the root sends a token down the set's links and each robot takes the robot
   its first token came from as its parent (:mod:`pipeline.consistency.roots`, the robots'
   protocol, which robot processes run: ``robots_solve``; the simulator evaluates it in
   batch, :func:`.gather.solve_at_roots`, counted as a shortest-path tree, and the two are
   property-tested to cut alike). The root solves the rule's solution on
   the set's bundles (:func:`~pipeline.consistency.evidence.solve_set`: triangle support
   with the three-view test, the Kruskal merge by decreasing evidence with the geometric
   test of the merged track) and sends the links it cuts down the tree; each robot cuts
   its side of them (reason of the rule; a cut history link is ignored, as in the rule's
   pass). Unlike a conflictive set, whose robots all solve alike (no reject messages), a
   conflict-free set needs no symmetric solving: one solution sent down costs far fewer
   bytes than every bundle flooded to every robot. In a conflict-free set the merge
   never meets two features of one image: what it cuts is what the geometric test refutes,
   so a set with a frame of unknown pose is not weighed (it would cut nothing). Why: a
   clash splits a set as soon as it appears, and the pieces are conflict-free from then on;
   a spurious link whose set never becomes conflictive again was never weighed, while the
   batch run sees the uncut history, where the set is conflictive and the merge's
   geometric test cuts it (``bench/online_cuts.py``, seed 0, ``H = 2``, before the
   weighing: of the 290 spurious links the batch cut and the online run kept, 5 were ever
   in a conflictive set while open, all 290 in a set a step's new links touched; with the
   weighing the run keeps 154 spurious links, the batch 552, and the online pairwise F1 of
   ``bench/online.py`` reaches the batch's). Each
   step re-weighs a touched set with what the window holds then (more frames, more
   triangles, a longer track for the geometric test): a link stays open to it for ``W + H``
   steps.
3. *History check.* A set the new links formed may join two retired pieces that hold one
   retired image (two features of one retired frame), which the window alone cannot show.
   Every member of a set knows the set after the detection (Prop. 3.5: its row is the whole
   set); in a set that reaches two pieces or more, the set's robots flood the pieces' names
   and entries (8 bytes per piece and :data:`RETIRED_ENTRY_BYTES` per entry, per robot of the
   set, in the detection's rounds) and check whether one robot has overlapping runs in two
   pieces. A conflictive set floods its open links too (24 bytes each per robot) and each
   of its robots solves the same deterministic repair, the rule of *when new evidence
   overturns an earlier decision*: a link between two retired frames is final (its piece is
   only summarized, it can no longer be split); every other kept link of the set, new, or
   older with an end in the window (window links and border links: *open* links), is
   weighed again with the new ones. The repair starts from the set's retired pieces, adds
   its open links by decreasing quality (ties by link id; the order of the evidence rule's
   Kruskal merge) and skips a link that would join two groups in which one robot has
   overlapping runs (window frames count as runs of one step). A skipped link is cut with
   reason ``history``: when a weak link into a retired frame closes the clash, it is that
   link that goes, not the stronger new one. (``overturn=False``: the earlier rule, which
   starts from the set's old links and history links and skips only new links, so new
   evidence never overturns an earlier decision.) By default (``robots_check``, with
   ``overturn``) the stage's robots run this check themselves after the rule, one robot per
   window frame of the sub-problem, messages only over the sub-problem's links
   (:mod:`pipeline.consistency.history`: a label flooding of the two smallest pieces each
   set reaches, which names the sets after the rule's cuts; an echo from each set with two
   pieces or a frame twice gathers the pieces' entries at a root; a bad set's open links go
   up that tree, the root computes the repair, the cut links go down, each robot cuts its
   side); the record applies their cuts and counts their messages (``history_rounds``,
   ``history_bytes``: above all the label flooding, which the estimate above takes as known
   from the detection) in place of the estimate. Property-tested to cut as the record's
   check (``robots_check=False``, which keeps the estimate: ``bench/online.py
   --record-check``).
4. Every set of the sub-problem gets a fresh label.

Earlier decisions: a cut link is never restored. A kept link is cut only at a step whose new
links touch its set: by the rule (reason of the rule) when they make it conflictive, by the
rule's merge (step 2b, reason of the rule) when its geometric test refutes it, or by the
history repair (an open link of a set holding a retired frame twice); a link between two
retired frames is final; every other kept link keeps its decision, and the labels of
untouched tracks do not change.

Guarantee (after every step the kept association is conflict-free), by induction on the
steps. Before the first step there is no link. Suppose the association is conflict-free
after step ``t - 1``. At step ``t`` only sets reached by a new link can change: a set no new
link reaches keeps its links (the stage runs on touched labels only; cuts happen only in the
sub-problem), so it stays conflict-free. A set the new links reach is, after the step, a
component of the sub-problem's kept links plus history links, together with the retired
pieces its border links reach (a retired feature is joined to the window only through a
piece's border links, which the history links chain). The rule leaves every component of the
sub-problem conflict-free over window images (Prop. 4.5 for Alg. 1; one pass of the
evidence rule); the weighing of step 2b only cuts links, which splits sets. If the rule cut
a history link (which stays), or two pieces of a component
share a retired image (then one robot has overlapping runs in both: runs cover every frame
of their piece), the repair rebuilds the component from conflict-free groups (its retired
pieces, each conflict-free by the induction; with ``overturn=False`` the groups its old
links joined before the step) and adds a link only when no robot has overlapping runs in the
two groups it joins, a superset of "the two groups share an image": the result is
conflict-free (a cut only splits sets, so the other components stay conflict-free). Hence a conflict created
by new links is always found: it lies in a set that contains a new link, whose labels are
touched, so it is inside the sub-problem (window images, caught by detection, Prop. 3.5) or
in two retired pieces of the set (caught by the history check).

What each robot knows after a step: for each of its window features, its label and, from
the detection, the members of its set within the window; for each of its border links, the
retired piece's name; for each live piece it has retired frames in, its runs of steps;
every link it holds, kept or cut, with the step. During a step, a robot of a set the stage
weighs (step 2 or 2b) holds that set's bundles: the keypoints, links, weights and
projections of the set's window features; it drops them once it has cut its side, so its
memory still follows window + hold.

Costs: rounds, messages and bytes are the simulator's counts of the sub-problem's stage
(images are its cameras, so messages between two frames of one robot are counted as if
sent: an upper bound on what goes over the air), plus the label exchange of the new links,
the names of retired pieces (step 1), the weighing and the gathering of the small
conflictive sets (step 2b: each bundle, ``128 + 16 deg`` bytes, one message per hop from its
robot to the root, the cut links, 16 bytes each, one message down each tree edge;
``2 ecc(root) + 1`` rounds, counted in the resolution phase beside the rule's;
``weigh_bytes``, ``weigh_messages``, ``weigh_rounds``) and the history
flood. The bookkeeping of this class (arrays of all links and features) is
the simulator's record, not a robot's memory: :meth:`OnlineAssociation.robot_state_bytes`
counts what a robot holds.

References
----------
R. Aragüés, E. Montijano, C. Sagüés, "Consistent data association in multi-robot systems
with limited communications", RSS 2010 — Sec. III (detection, Prop. 3.5), Sec. IV (Alg. 1,
Prop. 4.5).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from pipeline.consistency.engines.driver import resolve_conflicts
from pipeline.consistency.engines.gather import solve_at_roots
from pipeline.consistency.history import overlapping_runs, rebuild, runs_by_robot
from pipeline.consistency.rules import DEFAULT_RESOLUTION, get_rule
from pipeline.errors import InputError
from pipeline.progress import counted
from pipeline.types import Links

__all__ = ["Frame", "OnlineAssociation", "batch_resolve", "default_hold",
           "simulated_stage", "HISTORY",
           "LABEL_BYTES", "RETIRED_ENTRY_BYTES", "FLOOD_LINK_BYTES"]

FRESH_LABELS = 1 << 40
"""First fresh label name: a set no retired frame anchors is named from here on."""

WEIGHED_RULE = "evidence"
"""The rule whose merge weighs the conflict-free sets of a step (step 2b of the module
docstring): its stage cuts only in conflictive sets of at most ``B`` features (and merges the
larger ones); ``sync`` merges every set already, ``paper``'s Alg. 1 has no weights."""

HISTORY = "history"
"""Reason of a link cut by the history repair (step 3 of the module docstring)."""

LABEL_BYTES = 8
"""Bytes of one label on the wire (int64)."""
RETIRED_ENTRY_BYTES = 16
"""Bytes of one retired entry, held or flooded: a piece name (int64) and a run of steps
(two int32; the robot is the holder)."""
FLOOD_LINK_BYTES = 24
"""Bytes of one link in the history flood (two global feature ids and a float32 quality)."""
RUNS_PER_ROBOT = 4
"""Step runs a retired piece keeps per robot (:meth:`OnlineAssociation._add_entries`)."""


@dataclass
class Frame:
    """One robot's new frame as the stage sees it.

    robot : int; m : int — its number of features; keypoints : (m, 2) or None;
    projection : (3, 4) ``K [R | t]`` or None (the evidence rule's geometric test).
    """

    robot: int
    m: int
    keypoints: np.ndarray | None = None
    projection: np.ndarray | None = None


@dataclass
class _LinkTable:
    ci: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    fi: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    cj: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    fj: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    quality: np.ndarray = field(default_factory=lambda: np.zeros(0))
    kept: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    reason: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=object))
    step_added: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    step_cut: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))


class OnlineAssociation:
    """The association of a team in motion, grown one step at a time (module docstring).

    Parameters
    ----------
    window : int >= 1 — steps of frames a robot holds
    resolution : a rule of :mod:`pipeline.consistency.rules`
    overturn : bool — the history repair may cut open links older than the step (default;
        module docstring, step 3), or only new links
    hold : int >= 0 or None — steps a frame stays in the stage (its links open) after it
        leaves the matching window; None: ``window - 1`` (module docstring, *Hold*)
    weigh : bool — every set the step's new links touch is weighed by the rule's merge
        (default; module docstring, step 2b), or only the conflictive ones (the earlier rule)
    gather : bool — the evidence rule's conflictive sets of at most ``B`` features are solved
        at their roots too, their bundles gathered as in step 2b (default; the same cuts), or
        by the rule's own flood to every robot of the set (module docstring, step 2)
    stage : callable or None — runs the rule's stage of a step on its sub-problem:
        ``stage(features_per_image, links, resolution, *, solve_small_sets, keypoints,
        projections) -> ConsistencyResult`` with the images as cameras and images sharing a
        link as neighbours; None: the simulator (:func:`simulated_stage`). The job
        ``online_stage`` of a transport (:mod:`pipeline.runs.transports`), e.g. robot
        processes over Zenoh; every decision is the rule's, so the same on any transport
    robots_solve : bool — the sets of steps 2 (with ``gather``) and 2b are solved by the
        stage's robots at their roots (:mod:`pipeline.consistency.roots`; the stage is then
        called with ``gather_conflictive``, ``gather_free``), as a transport whose robots are
        processes must; False (default): by the simulator's batched solution of the same
        protocol (:func:`.gather.solve_at_roots`: the same cuts, property-tested)
    robots_check : bool — with ``overturn``, the stage's robots run the history check
        (step 3, :mod:`pipeline.consistency.history`; the stage is called with ``history``,
        one :class:`~pipeline.consistency.history.HistoryInputs` per image), and its costs
        are their messages (default); False: the record's own check, the same cuts
        (property-tested), its cost the estimate of step 3

    Examples
    --------
    Two robots; at step 0 feature 0 of image 0 (robot 0) is linked to image 1 (robot 1). The
    frames of step 1 (images 2 and 3) link to feature 1 of image 0, to image 1 and to each
    other: a chain that puts both features of image 0 in one set, which the step cuts:

    >>> from pipeline.types import Links
    >>> oa = OnlineAssociation(window=2, resolution="paper")
    >>> _ = oa.add_step([Frame(0, 2), Frame(1, 1)], Links([0], [0], [1], [0]))
    >>> rec = oa.add_step([Frame(0, 1), Frame(1, 1)],
    ...                   Links([0, 1, 2], [1, 0, 0], [2, 3, 3], [0, 0, 0]))
    >>> rec["links_new"], rec["conflictive_features"] > 0, rec["cut"] >= 1
    (3, True, True)
    >>> oa.is_conflict_free()
    True
    """

    def __init__(self, window: int, resolution: str = DEFAULT_RESOLUTION,
                 overturn: bool = True, hold: int | None = None, weigh: bool = True,
                 gather: bool = True, stage=None, robots_solve: bool = False,
                 robots_check: bool = True):
        if isinstance(window, bool) or not isinstance(window, (int, np.integer)) or window < 1:
            raise InputError(f"window {window!r}: expected a number of steps >= 1")
        self.window = int(window)
        if hold is None:
            hold = default_hold(self.window)
        if isinstance(hold, bool) or not isinstance(hold, (int, np.integer)) or hold < 0:
            raise InputError(f"hold {hold!r}: expected a number of steps >= 0 (0: a frame's "
                             "links are final as soon as it leaves the matching window)")
        self.hold = int(hold)
        self.overturn = bool(overturn)
        self.weigh = bool(weigh)
        self.gather = bool(gather)
        self.stage = stage or simulated_stage
        self.robots_solve = bool(robots_solve)
        self.robots_check = bool(robots_check)
        self.rule = get_rule(resolution)
        self.resolution = self.rule.name
        self.t = -1
        self.robot = np.zeros(0, np.int64)      # per image
        self.step = np.zeros(0, np.int64)       # per image
        self.m = np.zeros(0, np.int64)          # per image
        self.offset = np.zeros(1, np.int64)     # per image + 1
        self.keypoints: list = []
        self.projection: list = []
        self.label = np.zeros(0, np.int64)      # per feature
        self.degree = np.zeros(0, np.int64)     # kept links per feature
        self.piece = np.zeros(0, np.int64)      # per retired feature: its retired piece, or -1
        self._fresh = FRESH_LABELS              # next fresh label name
        self._fresh_piece = 0                   # next retired piece name
        self.links = _LinkTable()
        self.window_images = np.zeros(0, np.int64)
        self.window_links = np.zeros(0, np.int64)  # ids of links with both ends in the window
        self.border_links = np.zeros(0, np.int64)  # ids of kept links window -> retired
        # retired entries of live pieces: (piece, robot, lo, hi), the robot's frames of steps
        # lo..hi in the piece (at most RUNS_PER_ROBOT per piece and robot)
        self.ret_piece = np.zeros(0, np.int64)
        self.ret_robot = np.zeros(0, np.int64)
        self.ret_lo = np.zeros(0, np.int64)
        self.ret_hi = np.zeros(0, np.int64)
        self.steps: list[dict] = []
        self.last_sub = np.zeros(0, np.int64)  # features of the last step's sub-problem

    # ---------------------------------------------------------------- views of the record
    @property
    def n_images(self) -> int:
        return int(len(self.m))

    def all_links(self) -> Links:
        """Every link ever made, in arrival order (cameras = images)."""
        L = self.links
        return Links(L.ci, L.fi, L.cj, L.fj, L.quality)

    def kept_links(self) -> Links:
        return self.all_links().subset(self.links.kept)

    def is_conflict_free(self) -> bool:
        """Centralized check of the whole kept association (union-find; evaluation only)."""
        from pipeline.consistency.centralized import is_conflict_free

        return bool(is_conflict_free(self.m, self.kept_links()))

    def robot_state_bytes(self) -> np.ndarray:
        """Bytes each robot holds for the stage, ``(n_robots,)``: for its window frames'
        features a label and a link count (16 bytes each), the window links it holds (40
        bytes each: two ids, two features, quality), its border links (16 bytes each: its
        feature and the retired piece's name) and its retired entries (16 bytes each: piece
        and image). Descriptors are the matcher's, counted by the caller."""
        n = int(self.robot.max()) + 1 if len(self.robot) else 0
        out = np.zeros(n, np.int64)
        w = self.window_images
        np.add.at(out, self.robot[w], 16 * self.m[w])
        wl = self.window_links
        np.add.at(out, self.robot[self.links.ci[wl]], 40)
        np.add.at(out, self.robot[self.links.cj[wl]], 40)
        np.add.at(out, self.robot[self._border_ends()[2]], 16)
        np.add.at(out, self.ret_robot, RETIRED_ENTRY_BYTES)
        return out

    # ---------------------------------------------------------------- one step
    def add_step(self, frames: list[Frame], links: Links) -> dict:
        """Add a step's frames and new links, run the stage on what they touch.

        ``frames`` get the image ids ``n_images, n_images + 1, ...`` in their order; ``links``
        use those ids (cameras = images). Returns the step's record (also appended to
        :attr:`steps`): ``step``, ``links_new``, ``touched_labels``, ``sub_images``,
        ``sub_features``, ``sub_links``, ``history_links``, ``conflictive_features``
        (found by the step's first detection), ``conflictive_sets`` (resolved by the rule),
        ``weighed_sets`` (the conflict-free sets weighed, step 2b, with ``weigh_rounds``,
        ``weigh_messages``, ``weigh_bytes``, counted in ``rounds``, ``messages``, ``bytes``),
        ``cut`` (``cut_rule``, ``cut_weigh``, ``cut_history``, ``cut_old``: of them, links
        made at an earlier step), ``rounds`` (detection + resolution rounds), ``messages``, ``bytes``
        (of them ``retire_bytes``: the names of retired pieces, step 1), ``wall_s``,
        ``robot_state_bytes_max``, ``retired_entries_max`` (a robot's retired entries),
        ``stage_peak_bytes`` (the stage's peak over its images).

        Raises
        ------
        InputError
            A link breaks Assumptions 2.1–2.3, has no end in the step's frames or an end
            outside the window.
        """
        t0 = time.perf_counter()
        self.last_sub = np.zeros(0, np.int64)
        self.t += 1
        t = self.t
        first = self.n_images
        self._add_frames(frames, t)
        retire_msgs, retire_bytes = self._retire(t)
        new_ids = self._add_links(links, first, t)
        rec = dict(step=t, frames=len(frames), links_new=int(len(new_ids)), touched_labels=0,
                   sub_images=0, sub_features=0, sub_links=0, history_links=0,
                   conflictive_features=0, conflictive_sets=0, cut=0, cut_rule=0,
                   cut_weigh=0, cut_history=0, cut_old=0, weighed_sets=0, weigh_rounds=0,
                   weigh_messages=0, weigh_bytes=0, rounds=0, detection_rounds=0,
                   resolution_rounds=0, large_sets=0, merge_rounds=0, messages=0, bytes=0,
                   stage_peak_bytes=0, history_bytes=0)
        if self.robots_check and self.overturn:  # a step without new links has them too
            rec["history_rounds"] = 0
        if len(new_ids):
            self._stage(new_ids, t, rec)
        rec["messages"] += retire_msgs
        rec["bytes"] += retire_bytes
        rec["retire_bytes"] = retire_bytes
        state = self.robot_state_bytes()
        rec["robot_state_bytes_max"] = int(state.max(initial=0))
        per = np.bincount(self.ret_robot, minlength=len(state))
        rec["retired_entries_max"] = int(per.max(initial=0))
        rec["wall_s"] = time.perf_counter() - t0
        self.steps.append(rec)
        return rec

    def _add_frames(self, frames: list[Frame], t: int) -> None:
        for fr in frames:
            m = int(fr.m)
            if m < 0:
                raise InputError(f"frame of robot {fr.robot}: {m} features")
            g = self.n_images
            self.robot = np.append(self.robot, int(fr.robot))
            self.step = np.append(self.step, t)
            self.m = np.append(self.m, m)
            self.offset = np.append(self.offset, self.offset[-1] + m)
            self.keypoints.append(np.zeros((m, 2)) if fr.keypoints is None
                                  else np.asarray(fr.keypoints, np.float64))
            self.projection.append(fr.projection)
            base = self.offset[g]
            self.label = np.concatenate([self.label, base + np.arange(m, dtype=np.int64)])
            self.degree = np.concatenate([self.degree, np.zeros(m, np.int64)])
            self.piece = np.concatenate([self.piece, np.full(m, -1, np.int64)])
            self.window_images = np.append(self.window_images, g)

    def _border_ends(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Of each border link: its window feature, its retired feature's piece, and the
        window feature's image."""
        a, b = self._ends(self.border_links)
        win_a = self.piece[a] < 0
        w, r = np.where(win_a, a, b), np.where(win_a, b, a)
        return w, self.piece[r], np.searchsorted(self.offset, w, side="right") - 1

    def _retire(self, t: int) -> tuple[int, int]:
        """Step 1: frames older than window + hold retire; their kept links become final.

        Returns the messages and bytes that name the retired pieces (module docstring)."""
        old = self.window_images[self.step[self.window_images] <= t - self.window - self.hold]
        if not len(old):
            return 0, 0
        L = self.links
        feats = np.concatenate([self.offset[g] + np.arange(self.m[g]) for g in old])
        imgs = np.repeat(old, self.m[old])
        tracked = self.degree[feats] > 0
        f_new, img_new = feats[tracked], imgs[tracked]
        wl, bl = self.window_links, self.border_links
        gone_i, gone_j = np.isin(L.ci[wl], old), np.isin(L.cj[wl], old)
        a_w, b_w = self._ends(wl)
        inside = L.kept[wl] & gone_i & gone_j          # both ends retire now
        border_new = L.kept[wl] & (gone_i != gone_j)   # one end retires now
        # the border links whose window end retires now join an older piece
        w_b, p_b, _ = self._border_ends()
        closing = np.isin(w_b, f_new)
        # pieces: components of the newly retired features and the older pieces they touch
        old_p = np.unique(p_b[closing])
        k = len(f_new)
        node_a = np.concatenate([np.searchsorted(f_new, a_w[inside]),
                                 np.searchsorted(f_new, w_b[closing])])
        node_b = np.concatenate([np.searchsorted(f_new, b_w[inside]),
                                 k + np.searchsorted(old_p, p_b[closing])])
        n_nodes = k + len(old_p)
        adj = sp.coo_matrix((np.ones(len(node_a)), (node_a, node_b)), shape=(n_nodes, n_nodes))
        comp = connected_components(adj, directed=False)[1].astype(np.int64)
        # a component keeps the smallest name of the older pieces it holds, else a fresh name
        none = np.iinfo(np.int64).max
        name = np.full(comp.max() + 1 if n_nodes else 0, none, np.int64)
        np.minimum.at(name, comp[k:], old_p)
        fresh = np.flatnonzero(name == none)
        name[fresh] = self._fresh_piece + np.arange(len(fresh))
        self._fresh_piece += int(len(fresh))
        self.piece[f_new] = name[comp[:k]]
        renamed = 0
        if len(old_p):
            rename = name[comp[k:]]
            moved = rename != old_p
            if moved.any():
                on = np.isin(self.ret_piece, old_p[moved])
                renamed = int(on.sum())
                self.ret_piece[on] = rename[np.searchsorted(old_p, self.ret_piece[on])]
                on = np.isin(self.piece, old_p[moved])
                self.piece[on] = rename[np.searchsorted(old_p, self.piece[on])]
        self._add_entries(self.piece[f_new], self.robot[img_new], self.step[img_new])
        self.window_images = np.setdiff1d(self.window_images, old)
        self.window_links = wl[~(gone_i | gone_j)]
        self.border_links = np.concatenate([bl[~closing], wl[border_new]])
        self._drop_dead_pieces()
        # the robot of a retiring feature names its piece over each new border link; a
        # renamed piece's entries learn the new name (8 bytes each)
        n_msgs = int(border_new.sum()) + renamed
        return n_msgs, LABEL_BYTES * n_msgs

    def _add_links(self, links: Links, first: int, t: int) -> np.ndarray:
        from pipeline.association import check_links

        check_links(links, self.m)
        new_img = (links.cam_i >= first) | (links.cam_j >= first)
        # a new link joins frames of the matching window (the held frames take no new link)
        recent = self.window_images[self.step[self.window_images] > t - self.window]
        in_window = np.isin(links.cam_i, recent) & np.isin(links.cam_j, recent)
        bad = np.flatnonzero(~new_img | ~in_window)
        if bad.size:
            k = bad[0]
            raise InputError(f"new link {k} ({links.cam_i[k]},{links.feat_i[k]})-"
                             f"({links.cam_j[k]},{links.feat_j[k]}): a new link joins a frame of "
                             f"this step to a frame in the window of {counted(self.window, 'step')}")
        L = self.links
        n0 = len(L.ci)
        k = len(links)
        L.ci = np.concatenate([L.ci, links.cam_i])
        L.fi = np.concatenate([L.fi, links.feat_i])
        L.cj = np.concatenate([L.cj, links.cam_j])
        L.fj = np.concatenate([L.fj, links.feat_j])
        L.quality = np.concatenate([L.quality, links.quality])
        L.kept = np.concatenate([L.kept, np.ones(k, bool)])
        L.reason = np.concatenate([L.reason, np.full(k, "", dtype=object)])
        L.step_added = np.concatenate([L.step_added, np.full(k, t, np.int64)])
        L.step_cut = np.concatenate([L.step_cut, np.full(k, -1, np.int64)])
        ids = np.arange(n0, n0 + k, dtype=np.int64)
        self.window_links = np.concatenate([self.window_links, ids])
        np.add.at(self.degree, self.offset[links.cam_i] + links.feat_i, 1)
        np.add.at(self.degree, self.offset[links.cam_j] + links.feat_j, 1)
        return ids

    def _ends(self, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        L = self.links
        return self.offset[L.ci[ids]] + L.fi[ids], self.offset[L.cj[ids]] + L.fj[ids]

    def _stage(self, new_ids: np.ndarray, t: int, rec: dict) -> None:
        L = self.links
        a_new, b_new = self._ends(new_ids)
        touched = np.unique(np.concatenate([self.label[a_new], self.label[b_new]]))
        # sub-problem: window features of touched labels (new features are their own labels)
        w = self.window_images
        wfeat = np.concatenate([self.offset[g] + np.arange(self.m[g]) for g in w]) if len(w) \
            else np.zeros(0, np.int64)
        sub = wfeat[np.isin(self.label[wfeat], touched)]
        self.last_sub = sub
        wl = self.window_links
        a_w, _ = self._ends(wl)
        old_ids = wl[L.kept[wl] & (L.step_added[wl] < t) & np.isin(self.label[a_w], touched)]
        # history links: the window features each retired piece holds, chained (exact: a
        # piece is connected, so are the window features its border links reach)
        w_b, p_b, _ = self._border_ends()
        on = np.isin(w_b, sub)
        att_f, att_p = w_b[on], p_b[on]
        hist_a, hist_b = _chain(att_f, att_p)
        real = np.concatenate([old_ids, new_ids])
        a_r, b_r = self._ends(real)
        # a history link that doubles a real link is left out of the detection (the real
        # link stands for it there; cutting it would not split the set: the check below
        # still counts the history link)
        n_f = len(self.label)
        det = ~np.isin(np.minimum(hist_a, hist_b) * n_f + np.maximum(hist_a, hist_b),
                       np.minimum(a_r, b_r) * n_f + np.maximum(a_r, b_r))
        a_all = np.concatenate([a_r, hist_a[det]])
        b_all = np.concatenate([b_r, hist_b[det]])
        q_all = np.concatenate([L.quality[real], np.ones(int(det.sum()))])
        n_real = len(real)
        # images of the sub-problem are its cameras
        img_of = np.searchsorted(self.offset, sub, side="right") - 1
        images = np.unique(img_of)
        rec.update(touched_labels=int(len(touched)), sub_images=int(len(images)),
                   sub_features=int(len(sub)), sub_links=int(n_real),
                   history_links=int(len(hist_a)))
        local_links = self._local_links(images, a_all, b_all, q_all)
        kw = {}
        if self.rule.needs_evidence:
            kw = dict(keypoints=[self.keypoints[g] for g in images],
                      projections=[self.projection[g] for g in images]
                      if all(self.projection[g] is not None for g in images) else None)
        gather = self.gather and self.rule.name == WEIGHED_RULE
        by_robots = self.robots_solve and self.rule.name == WEIGHED_RULE \
            and (gather or self.weigh)
        if by_robots:  # each image's own projection, None where unknown (a set with one
            # is solved without the geometric test, as in the batched solution; with no pose
            # at all no conflict-free set is weighed: it would cut nothing)
            posed = [self.projection[g] for g in images]
            kw.update(gather_conflictive=gather,
                      gather_free=self.weigh and any(P is not None for P in posed),
                      projections=posed)
        robots_check = self.robots_check and self.overturn
        # the weighing solved in batch by the simulator cuts after the stage: the robots'
        # check then runs after it, on the simulator's robots (else within the stage)
        weigh_after = (self.weigh or gather) and self.rule.name == WEIGHED_RULE \
            and not by_robots
        hist_in = None
        if robots_check:  # step 3 by the stage's robots (pipeline.consistency.history)
            hist_in = self._history_inputs(images, local_links, real, hist_a, hist_b, sub)
            if not weigh_after:
                kw["history"] = hist_in
        res = self.stage(self.m[images], local_links, self.resolution,
                         solve_small_sets=not gather, **kw)
        st = res.stats
        first = st["per_iteration"][0] if st["per_iteration"] else {}
        rec.update(conflictive_features=int(first.get("conflictive_features", 0)),
                   conflictive_sets=int(sum(p.get("conflictive_sets", 0)
                                            for p in st["per_iteration"])),
                   detection_rounds=int(st["detection_rounds"]),
                   resolution_rounds=int(st["resolution_rounds"]),
                   large_sets=int(st.get("large_sets", 0)),
                   merge_rounds=int(st.get("merge_rounds", 0)),
                   messages=int(st["messages"]), bytes=int(st["bytes"]),
                   stage_peak_bytes=int(st["max_robot_memory_bytes"]))
        rec["bytes"] += 2 * LABEL_BYTES * len(new_ids)
        rec["messages"] += len(new_ids)  # counted as one message per link (both labels)
        cut = np.flatnonzero(res.deleted[:n_real])
        self._cut(real[cut], str(self.rule.name), t)
        rec["cut_rule"] = int(len(cut))
        # the sets the detection found conflict-free are weighed by the rule's merge too; the
        # small conflictive ones are solved there when gathered
        if (self.weigh or gather) and self.rule.name == WEIGHED_RULE:
            self._weigh(sub, img_of, images, real, n_real, a_all, b_all, q_all, t, rec,
                        st.get("bundle_budget"), conflict_free=self.weigh, conflictive=gather,
                        solved=res if by_robots else None)
        # history check and repair (step 3), then the new labels (step 4)
        if robots_check and weigh_after:
            from pipeline.consistency.engines.history_run import run_history

            alive = np.r_[L.kept[real], ~np.asarray(res.deleted, bool)[n_real:]]
            res.stats["history"] = run_history(self.m[images], local_links, alive, hist_in)
        hist_cut, flood = self._history_check(sub, real, hist_a, hist_b, att_f, att_p, t,
                                              res.stats.get("history") if robots_check
                                              else None)
        rec["cut_history"] = int(hist_cut)
        rec["bytes"] += int(flood)
        rec["history_bytes"] = int(flood)  # the record's estimate of the check's flood
        if robots_check:  # the robots' own phases: their rounds follow the rule's
            h = res.stats["history"]
            rec["history_rounds"] = int(h["rounds"])
            rec["history_bytes"] = int(h["bytes"])
            rec["resolution_rounds"] += int(h["rounds"])
            if not h.get("counted"):
                rec["messages"] += int(h["messages"])
            rec["stage_peak_bytes"] = max(rec["stage_peak_bytes"], int(h.get("peak_bytes", 0)))
        rec["rounds"] = rec["detection_rounds"] + rec["resolution_rounds"]
        rec["cut"] = rec["cut_rule"] + rec["cut_weigh"] + rec["cut_history"]
        rec["cut_old"] = int(((L.step_cut == t) & (L.step_added < t)).sum())

    def _weigh(self, sub, img_of, images, real, n_real, a_all, b_all, q_all, t: int,
               rec: dict, budget: int | None = None, *, conflict_free: bool = True,
               conflictive: bool = False, solved=None) -> None:
        """Step 2b of the module docstring: the rule's merge on every set of the sub-problem
        the detection found conflict-free (``conflict_free``) and, with ``conflictive``, on
        its conflictive sets of at most ``budget`` features (the rule's solution of step 2,
        gathered at the root instead of flooded to every robot of the set: the same bundles,
        so the same cuts, :func:`~pipeline.consistency.evidence.solve_set`; counted as the
        rule's: ``cut_rule``, ``conflictive_sets``; such a set is solved with the geometric
        test where every image of it is posed, without where not, as the rule does).

        The sets are the components of the sub-problem's links before the rule's cuts (real
        and history links, as the detection saw them); one without two features of one image
        is conflict-free and holds at most ``budget`` features (the rule's bundle budget
        ``B``, :func:`pipeline.consistency.setlists.bundle_budget`: a larger set got the
        rule's ``sync`` merge, conflictive or not) was left alone by the rule. A conflict-free
        set with an image of unknown pose is not weighed: without the geometric test the
        merge of a conflict-free set joins all of it (no two features of one image to keep
        apart), it would cut nothing. The sets are solved at their roots
        (:func:`.gather.solve_at_roots`: bundles up a shortest-path tree, the cut links back
        down; its module docstring gives the counts); each robot cuts its side. A cut
        history link is ignored, as in the rule's pass (it stands for a retired piece).

        ``solved``: the stage's result when its robots solved these sets themselves
        (``robots_solve``): their cuts are already made and counted as the rule's; here they
        are counted as this step's (``cut_weigh``, ``weighed_sets``; the bytes are in the
        stage's)."""
        comp = self._components(sub, a_all, b_all)
        posed = np.array([self.projection[g] is not None for g in images.tolist()], bool)
        dup = np.asarray(_duplicated_keys(comp, img_of), np.int64)
        unposed = np.unique(comp[~posed[np.searchsorted(images, img_of)]])
        # conflictive sets unless gathered here (else the rule's), and conflict-free sets
        # with an image of unknown pose (no test: the merge of a conflict-free set then joins
        # all of it) or not weighed at all, are left alone
        bad = dup if not conflictive else np.zeros(0, np.int64)
        free_bad = unposed if conflict_free else np.unique(comp)
        bad = np.union1d(bad, np.setdiff1d(free_bad, dup)).astype(np.int64)
        if budget is not None:  # the rule's large sets (more than B features)
            size = np.bincount(comp)
            bad = np.union1d(bad, np.flatnonzero(size > int(budget))).astype(np.int64)
        ia = np.searchsorted(sub, a_all)
        on = ~np.isin(comp[ia], bad)
        if not on.any():
            return
        cam = np.searchsorted(images, img_of)            # an image's camera in the stage
        P_img = np.stack([np.eye(3, 4) if p is None else np.asarray(p, np.float64)
                          for p in (self.projection[g] for g in images.tolist())]) \
            if len(images) else np.zeros((0, 3, 4))
        kp = np.concatenate([np.asarray(self.keypoints[g][sub[img_of == g] - self.offset[g]],
                                        np.float32) for g in images.tolist()]).astype(np.float64) \
            if len(sub) else np.zeros((0, 2))  # sub ascends, so do its images: kp[i] is sub[i]'s
        is_real = np.arange(len(a_all)) < n_real          # a cut history link is ignored
        if solved is None:
            sol = solve_at_roots(sub, cam, a_all, b_all, q_all, on, comp, kp, P_img, unposed,
                                 is_real, len(images))
            ks, cut, set_of, sets = sol.links, sol.cut, sol.set_of, sol.sets
        else:  # cut by the stage's robots (and counted in its rounds, messages and bytes)
            ks = np.flatnonzero(on)
            ks = ks[np.argsort(comp[ia[ks]], kind="stable")]
            cut = np.asarray(solved.deleted, bool)[ks]
            set_of = comp[ia[ks]]
            sets = np.unique(set_of)
        in_dup = np.isin(set_of, dup)                      # a link of a conflictive set
        cut_ids = real[ks[cut & is_real[ks]]]
        self._cut(cut_ids, str(self.rule.name), t)
        n_rule = int((cut & is_real[ks] & in_dup).sum())
        n_dup = int(np.isin(sets, dup).sum())
        a_s, b_s = a_all[ks], b_all[ks]
        if solved is not None:  # the stage counted all its cuts, and their ends, as the rule's
            rec["cut_rule"] -= int(len(cut_ids))
            rec["conflictive_features"] -= int(len(np.unique(np.r_[a_s[cut], b_s[cut]])))
        rec["cut_rule"] += n_rule
        rec["conflictive_sets"] += n_dup
        rec["conflictive_features"] += int(len(np.unique(np.r_[a_s[cut & in_dup],
                                                                b_s[cut & in_dup]])))
        rec.update(weighed_sets=int(len(sets)) - n_dup, cut_weigh=int(len(cut_ids)) - n_rule)
        if solved is not None:
            roots = solved.stats.get("roots", {})
            rec.update(weigh_rounds=int(roots.get("rounds", 0)),
                       weigh_messages=int(roots.get("messages", 0)),
                       weigh_bytes=int(roots.get("bytes", 0)))
            return
        rec.update(weigh_rounds=sol.rounds, weigh_messages=sol.messages, weigh_bytes=sol.nbytes)
        rec["resolution_rounds"] = max(rec["resolution_rounds"], sol.rounds)
        rec["messages"] += sol.messages
        rec["bytes"] += sol.nbytes
        rec["stage_peak_bytes"] = max(rec["stage_peak_bytes"], int(sol.held.max(initial=0)))

    def _local_links(self, images, a, b, q) -> Links:
        img_a = np.searchsorted(self.offset, a, side="right") - 1
        img_b = np.searchsorted(self.offset, b, side="right") - 1
        ca, cb = np.searchsorted(images, img_a), np.searchsorted(images, img_b)
        fa, fb = a - self.offset[img_a], b - self.offset[img_b]
        swap = ca > cb
        return Links(np.where(swap, cb, ca), np.where(swap, fb, fa), np.where(swap, ca, cb),
                     np.where(swap, fa, fb), q)

    def changed_window_links(self) -> np.ndarray:
        """Ids of the kept window links of the sets the last step's stage ran on (both ends
        in its sub-problem): the tracks the step changed, e.g. for fusion."""
        wl = self.window_links[self.links.kept[self.window_links]]
        a, b = self._ends(wl)
        return wl[np.isin(a, self.last_sub) & np.isin(b, self.last_sub)]

    def cut(self, ids, reason: str) -> None:
        """Cut kept window links ``ids`` at the current step for a later stage's ``reason``
        (e.g. ``fusion-outlier``). Cutting only splits sets: the association stays
        conflict-free (labels may then name more than one set, which only makes the next
        checks look at more features)."""
        ids = np.asarray(ids, np.int64).reshape(-1)
        bad = ids[~np.isin(ids, self.window_links)]
        if bad.size:
            raise InputError(f"link {int(bad[0])}: only links between window frames can be "
                             "cut (a retired frame's links are final)")
        self._cut(ids, reason, self.t)

    def _cut(self, ids: np.ndarray, reason: str, t: int) -> None:
        L = self.links
        ids = ids[L.kept[ids]]
        L.kept[ids] = False
        L.reason[ids] = reason
        L.step_cut[ids] = t
        a, b = self._ends(ids)
        np.add.at(self.degree, a, -1)
        np.add.at(self.degree, b, -1)

    def _components(self, sub, a, b) -> np.ndarray:
        ia, ib = np.searchsorted(sub, a), np.searchsorted(sub, b)
        adj = sp.coo_matrix((np.ones(len(ia)), (ia, ib)), shape=(len(sub), len(sub)))
        return connected_components(adj, directed=False)[1].astype(np.int64)

    def _history_inputs(self, images, local_links: Links, real, hist_a, hist_b, sub
                        ) -> list:
        """What each stage camera's robot holds for step 3 run by the robots
        (:class:`~pipeline.consistency.history.HistoryInputs`): its frame's first global id,
        team robot and step; for each of its rows the link id (-1: a history link), quality
        and whether a history link joins its two features; its border links into retired
        pieces and those pieces' retired entries."""
        from pipeline.consistency.history import HistoryInputs

        L = self.links
        n_real = len(real)
        n_f = len(self.label)
        a_r, b_r = self._ends(real)
        hist_keys = np.minimum(hist_a, hist_b) * n_f + np.maximum(hist_a, hist_b)
        doubled = np.isin(np.minimum(a_r, b_r) * n_f + np.maximum(a_r, b_r), hist_keys)
        k_all = len(local_links)
        row_id = np.r_[real, np.full(k_all - n_real, -1, np.int64)]
        row_q = np.r_[L.quality[real], np.ones(k_all - n_real)]
        row_h = np.r_[doubled, np.ones(k_all - n_real, bool)]
        ll = local_links
        owner = np.r_[ll.cam_i, ll.cam_j]
        nbr, s_ = np.r_[ll.cam_j, ll.cam_i], np.r_[ll.feat_j, ll.feat_i]
        both = np.r_[np.arange(k_all), np.arange(k_all)]
        w_b, p_b, img_b = self._border_ends()
        on = np.isin(w_b, sub)
        b_ids = self.border_links[on]
        w_b, p_b, cam_b = w_b[on], p_b[on], np.searchsorted(images, img_b[on])
        # the head of each piece's chain: its smallest window feature (_chain's order)
        pieces, at = np.unique(p_b, return_inverse=True)
        first = np.full(len(pieces), np.iinfo(np.int64).max)
        np.minimum.at(first, at, w_b)
        head = w_b == first[at]
        # each camera's rows and border links, grouped once
        o_row = np.argsort(owner, kind="stable")
        at_row = np.searchsorted(owner[o_row], np.arange(len(images) + 1))
        o_b = np.argsort(cam_b, kind="stable")
        at_b = np.searchsorted(cam_b[o_b], np.arange(len(images) + 1))
        out = []
        for c, g in enumerate(images.tolist()):
            rows = o_row[at_row[c]:at_row[c + 1]]
            mine = o_b[at_b[c]:at_b[c + 1]]
            ent = np.isin(self.ret_piece, p_b[mine])
            out.append(HistoryInputs(
                int(self.offset[g]), int(self.robot[g]), int(self.step[g]),
                nbr[rows], s_[rows], row_id[both[rows]], row_q[both[rows]],
                row_h[both[rows]], w_b[mine] - self.offset[g], p_b[mine], b_ids[mine],
                L.quality[b_ids[mine]], head[mine], self.ret_piece[ent], self.ret_robot[ent],
                self.ret_lo[ent], self.ret_hi[ent]))
        return out

    def _history_check(self, sub, real, hist_a, hist_b, att_f, att_p, t: int,
                       robots: dict | None = None) -> tuple[int, int]:
        """Step 3 of the module docstring: returns (links cut, flood bytes).

        The sets after the rule's cuts are the components of the kept links and the history
        links (a history link stands for a retired piece: it cannot be cut). A set is
        conflictive if it holds one window image twice (the rule cut a history link) or if
        two of its retired pieces share an image.

        ``robots``: the check as the stage's robots ran it (:mod:`pipeline.consistency.history`:
        ``cut`` the link ids they cut, ``bytes`` what they sent, counted here unless the stage
        counted it, ``counted``); the record then only applies their cuts and renames."""
        L = self.links
        if robots is not None:
            cut_ids = np.asarray(robots["cut"], np.int64)
            self._cut(cut_ids, HISTORY, t)
            bad = bool(len(cut_ids))
            flood = 0 if robots.get("counted") else int(robots["bytes"])
            return self._rename(sub, real, bad, len(cut_ids), flood)
        kept_real = real[L.kept[real]]
        a_k, b_k = self._ends(kept_real)
        comp = self._components(sub, np.concatenate([a_k, hist_a]),
                                np.concatenate([b_k, hist_b]))
        img_of = np.searchsorted(self.offset, sub, side="right") - 1
        w_all = self._border_ends()[0]
        # the pieces of each set and their retired entries
        pc = np.unique(np.stack([comp[np.searchsorted(sub, att_f)], att_p], axis=1), axis=0) \
            if len(att_f) else np.zeros((0, 2), np.int64)
        n_pieces = np.bincount(pc[:, 0], minlength=comp.max() + 1 if len(comp) else 0)
        pc = pc[np.argsort(pc[:, 1], kind="stable")]  # one set per piece (its chain)
        on = np.isin(self.ret_piece, pc[:, 1])
        r_comp = pc[np.searchsorted(pc[:, 1], self.ret_piece[on]), 0]
        r_piece, r_robot = self.ret_piece[on], self.ret_robot[on]
        r_lo, r_hi = self.ret_lo[on], self.ret_hi[on]
        # the flood: sets with two pieces or more compare their pieces' entries
        flood = 0
        many = np.flatnonzero(n_pieces >= 2)
        if len(many):
            robots_c = np.zeros(len(n_pieces), np.int64)
            key = np.unique(np.stack([comp, self.robot[img_of]], axis=1), axis=0)
            np.add.at(robots_c, key[:, 0], 1)
            entries_c = np.bincount(r_comp, minlength=len(n_pieces))
            flood += int((robots_c[many] * (RETIRED_ENTRY_BYTES * entries_c[many]
                                            + LABEL_BYTES * n_pieces[many])).sum())
        bad = set(_duplicated_keys(comp, img_of)) | \
            set(overlapping_runs(r_comp, r_robot, r_lo, r_hi))
        cut_n = 0
        for c in sorted(bad):
            members = np.flatnonzero(comp == c)
            robots = np.unique(self.robot[img_of[members]])
            in_c = np.isin(self.offset[L.ci[kept_real]] + L.fi[kept_real], sub[members])
            links_c = kept_real[in_c]
            here = r_comp == c
            entries = (r_piece[here], r_robot[here], r_lo[here], r_hi[here])
            if self.overturn:
                border_c = self.border_links[np.isin(w_all, sub[members])]
                flood += len(robots) * FLOOD_LINK_BYTES * int(len(links_c) + len(border_c))
                skipped = self._rebuild(sub, members, links_c, border_c, img_of, entries)
            else:
                flood += len(robots) * FLOOD_LINK_BYTES * int((L.step_added[links_c] == t).sum())
                skipped = self._repair(sub, members, links_c, hist_a, hist_b, img_of, att_f,
                                       att_p, entries, t)
            self._cut(skipped, HISTORY, t)
            cut_n += len(skipped)
        return self._rename(sub, real, bool(bad), cut_n, flood, comp)

    def _rename(self, sub, real, changed: bool, cut_n: int, flood: int, comp=None
                ) -> tuple[int, int]:
        """Step 4: every set of the sub-problem (after the history cuts) gets a fresh name;
        returns (links cut, flood bytes) for the caller."""
        L = self.links
        if changed:
            self.border_links = self.border_links[L.kept[self.border_links]]
            self._drop_dead_pieces()
        if changed or comp is None:
            w_b, p_b, _ = self._border_ends()
            on = np.isin(w_b, sub)
            hist_a, hist_b = _chain(w_b[on], p_b[on])
            kept_real = real[L.kept[real]]
            a_k, b_k = self._ends(kept_real)
            comp = self._components(sub, np.concatenate([a_k, hist_a]),
                                    np.concatenate([b_k, hist_b]))
        # step 4: every set of the sub-problem gets a fresh name
        n_c = int(comp.max()) + 1 if len(comp) else 0
        self.label[sub] = self._fresh + comp.astype(np.int64)
        self._fresh += n_c
        return cut_n, flood

    def _rebuild(self, sub, members, links_c, border_c, img_of, entries) -> np.ndarray:
        """The history repair of one conflictive set when open links may be overturned
        (step 3): the links it cuts. The set's retired pieces stay whole (their links are
        final); its open links, every kept window link and border link of the set, are added
        by decreasing quality (ties by link id), the order of the evidence rule's Kruskal
        merge, and a link is skipped when the two groups it would join have overlapping runs
        of one robot (:func:`pipeline.consistency.history.rebuild`, what the robots' check
        computes at the set's root). Deterministic."""
        L = self.links
        r_piece, r_robot, r_lo, r_hi = entries
        images: dict[int, dict] = {
            int(f): {int(self.robot[img_of[k]]): [(int(self.step[img_of[k]]),) * 2]}
            for k, f in zip(members, sub[members], strict=True)}
        for p in np.unique(r_piece).tolist():  # a piece is node -1 - p
            on = r_piece == p
            runs: dict = {}
            for r, lo, hi in zip(r_robot[on].tolist(), r_lo[on].tolist(), r_hi[on].tolist(),
                                 strict=True):
                runs.setdefault(r, []).append((lo, hi))
            images[-1 - p] = runs
        a_w, b_w = self._ends(links_c)
        a_b, b_b = self._ends(border_c)
        win_a = self.piece[a_b] < 0
        node_b = -1 - self.piece[np.where(win_a, b_b, a_b)]
        ids = np.concatenate([links_c, border_c])
        na = np.concatenate([a_w, np.where(win_a, a_b, b_b)])
        nb = np.concatenate([b_w, node_b])
        return rebuild(images, ids, na, nb, L.quality[ids])

    def _repair(self, sub, members, links_c, hist_a, hist_b, img_of, att_f, att_p,
                entries, t) -> np.ndarray:
        """The deterministic repair of one set (step 3): the new links it skips. A group of
        features holds, per robot, the step runs of its frames (window frames as runs of
        one step); two groups may join when no robot has overlapping runs in both."""
        L = self.links
        r_piece, r_robot, r_lo, r_hi = entries
        parent = {int(f): int(f) for f in sub[members]}
        images: dict[int, dict] = {
            int(f): {int(self.robot[img_of[k]]): [(int(self.step[img_of[k]]),) * 2]}
            for k, f in zip(members, sub[members], strict=True)}
        mem = set(parent)
        seen: set[int] = set()
        for f, p in zip(att_f.tolist(), att_p.tolist(), strict=True):
            if f in mem and p not in seen:   # a piece's runs go with one of its features
                seen.add(p)
                for r, lo, hi in zip(r_robot[r_piece == p].tolist(), r_lo[r_piece == p].tolist(),
                                     r_hi[r_piece == p].tolist(), strict=True):
                    images[f].setdefault(r, []).append((lo, hi))

        def clash(x: dict, y: dict) -> bool:
            return any(lo <= h and l2 <= hi for r in x.keys() & y.keys()
                       for lo, hi in x[r] for l2, h in y[r])

        def find(x):
            while parent[x] != x:
                parent[x] = parent[parent[x]]
                x = parent[x]
            return x

        def union(x, y, force: bool = False) -> bool:
            rx, ry = find(x), find(y)
            if rx == ry:
                return True
            if not force and clash(images[rx], images[ry]):
                return False
            if len(images[rx]) < len(images[ry]):
                rx, ry = ry, rx
            parent[ry] = rx
            for r, runs in images[ry].items():
                images[rx].setdefault(r, []).extend(runs)
            return True

        is_new = L.step_added[links_c] == t
        old, new = links_c[~is_new], links_c[is_new]
        a_o, b_o = self._ends(old)
        base = [(int(x), int(y)) for x, y in zip(a_o, b_o, strict=True)]
        base += [(int(x), int(y)) for x, y in zip(hist_a, hist_b, strict=True)
                 if int(x) in mem]
        for x, y in base:  # joined before this step (a clash here is the runs' summary's)
            union(x, y, force=True)
        new = new[np.lexsort((new, -L.quality[new]))]
        a_n, b_n = self._ends(new)
        skipped = [int(k) for k, x, y in zip(new, a_n, b_n, strict=True)
                   if not union(int(x), int(y))]
        return np.asarray(skipped, np.int64)

    def _drop_dead_pieces(self) -> None:
        """A retired piece no border link reaches belongs to a set with no window feature
        left: no new link can reach it, its entries go."""
        if not len(self.ret_piece):
            return
        live = np.isin(self.ret_piece, self._border_ends()[1])
        self.ret_piece, self.ret_robot = self.ret_piece[live], self.ret_robot[live]
        self.ret_lo, self.ret_hi = self.ret_lo[live], self.ret_hi[live]

    def _add_entries(self, piece, robot, step) -> None:
        """Add retired frames (one entry each) to the entries, then rewrite every (piece,
        robot) as its runs of consecutive steps; beyond :data:`RUNS_PER_ROBOT` runs its oldest
        runs become one run over their span (a superset of its frames: the history check
        may then see a clash that is not there, never miss one)."""
        p = np.concatenate([self.ret_piece, piece])
        r = np.concatenate([self.ret_robot, robot])
        lo = np.concatenate([self.ret_lo, step])
        hi = np.concatenate([self.ret_hi, step])
        if not len(p):
            return
        p, r, lo, hi, head, gid, run_max = runs_by_robot(p, r, lo, hi)
        start = head | np.r_[True, lo[1:] > run_max[:-1] + 1]
        p, r, lo, hi, gid = _reduce_runs(start, p, r, lo, hi, gid)
        # at most RUNS_PER_ROBOT runs per (piece, robot): its oldest runs merge into one
        g_head = np.r_[True, gid[1:] != gid[:-1]]
        k = np.cumsum(g_head) - 1
        rank = np.arange(len(k)) - np.flatnonzero(g_head)[k]
        extra = np.bincount(k)[k] - RUNS_PER_ROBOT  # runs 0..extra become one
        start = g_head | (rank > extra)
        p, r, lo, hi, _ = _reduce_runs(start, p, r, lo, hi, gid)
        self.ret_piece, self.ret_robot, self.ret_lo, self.ret_hi = p, r, lo, hi


def default_hold(window: int) -> int:
    """The default hold, ``window - 1`` steps (module docstring, *Hold*).

    >>> default_hold(3)
    2
    """
    return max(int(window) - 1, 0)


def _chain(f: np.ndarray, group: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Links chaining the items ``f`` of each group in order (``len(group) - 1`` per group).

    >>> [x.tolist() for x in _chain(np.array([5, 3, 9, 4]), np.array([1, 1, 1, 2]))]
    [[3, 5], [5, 9]]
    """
    if not len(f):
        z = np.zeros(0, np.int64)
        return z, z
    u = np.unique(np.stack([group, f], axis=1), axis=0)
    same = u[1:, 0] == u[:-1, 0]
    ab = np.unique(np.stack([u[:-1, 1][same], u[1:, 1][same]], axis=1), axis=0)
    return ab[:, 0], ab[:, 1]


def _reduce_runs(start, p, r, lo, hi, gid):
    """Runs beginning at ``start`` (rows sorted by piece, robot, lo) merged into one row."""
    at = np.flatnonzero(start)
    return p[at], r[at], lo[at], np.maximum.reduceat(hi, at), gid[at]


def simulated_stage(features_per_image, links: Links, resolution: str, *,
                     solve_small_sets: bool = True, keypoints=None, projections=None,
                     gather_conflictive: bool = False, gather_free: bool = False,
                     history=None):
    """The rule's stage of a step on the simulated network (the default ``stage``).

    ``history``: one :class:`~pipeline.consistency.history.HistoryInputs` per camera: the
    stage's robots then run the history check after the rule, on the links it kept
    (:func:`.history_run.run_history`), reported in ``stats['history']`` (its messages and bytes
    counted there, not in the stage's)."""
    res = resolve_conflicts(features_per_image, None, links, resolution=resolution,
                            solve_small_sets=solve_small_sets, keypoints=keypoints,
                            projections=projections, gather_conflictive=gather_conflictive,
                            gather_free=gather_free)
    if history is not None:
        from pipeline.consistency.engines.history_run import run_history

        res.stats["history"] = run_history(features_per_image, links, ~res.deleted, history)
    return res


def _duplicated_keys(group: np.ndarray, item: np.ndarray) -> list[int]:
    """Groups holding one item twice."""
    if not len(group):
        return []
    key = np.stack([group, item], axis=1)
    u, counts = np.unique(key, axis=0, return_counts=True)
    return np.unique(u[counts > 1, 0]).tolist()


def batch_resolve(features_per_image, links: Links, resolution: str = DEFAULT_RESOLUTION,
                  keypoints=None, projections=None):
    """The batch run the online stage is compared with: the same rule from scratch on all
    links so far (images as cameras, cameras sharing a link as neighbours)."""
    kw = {}
    if get_rule(resolution).needs_evidence:
        kw = dict(keypoints=keypoints, projections=projections)
    return resolve_conflicts(np.asarray(features_per_image, np.int64), None, links,
                             resolution=resolution, **kw)
