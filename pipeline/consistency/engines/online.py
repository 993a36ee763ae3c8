"""Online association: frames arrive step by step and the kept association stays conflict-free.

The papers take one snapshot (all images, one association). Here a team in motion adds one
frame per robot per step; :class:`OnlineAssociation` keeps every link ever made (kept or
cut, with the step that made and the step that cut it) and runs the distributed stage of
Aragüés et al. only on what the step's new links touch.

This module holds the record and drives each step: :class:`OnlineAssociation` reads a step's
frames and new links (:meth:`~OnlineAssociation.add_step`, called by
:mod:`pipeline.runs.online` once per step) and keeps the images, the labels, the link table
(kept or cut, with its reason and steps), the window, the border links and the retired
entries. Step 1 (retiring frames) and the retired entries are here; steps 2 to 4 are methods
of the class written beside it, one module each (:mod:`.online_detection`,
:mod:`.online_weigh`, :mod:`.online_history`); the guarantee below is of the whole step.
After each step the record answers the caller: the step's figures (returned and kept in
:attr:`~OnlineAssociation.steps`), the kept links, the links the step changed (for fusion),
and the cut links with their reasons.

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
2. *Incremental detection* (:mod:`.online_detection`). The stage runs only on the
   *sub-problem*: the window features of the labels the new links touch, the kept window
   links among them, the new links, and the *history links*, a chain through the window
   features each retired piece's border links reach (the detection sees the set whole). On
   it the simulator runs the rule of :mod:`pipeline.consistency.rules`, images as its
   cameras, until conflict-free (Prop. 3.5, Prop. 4.5; the evidence rule is a whole stage,
   its small conflictive sets solved at their roots as in step 2b: ``gather``).
2b. *Weighing the conflict-free sets* (``weigh``, default; :mod:`.online_weigh`). Every other
   set of the sub-problem, one the step's new links touched and the rule found
   conflict-free, is weighed by the evidence rule's merge too, solved at the set's root; a
   spurious link whose set is conflict-free still meets the merge's geometric test. It only
   cuts links.
3. *History check* (:mod:`.online_history`). A set the new links formed may join two retired
   pieces that hold one retired image, which the window alone cannot show: the set's robots
   compare the pieces' retired entries, and a conflictive set is repaired: starting from its
   retired pieces (final), its *open* links (new, or older with an end in the window) are
   added by decreasing quality, and a link that would join two groups in which one robot has
   overlapping runs is cut with reason ``history``.
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
from pipeline.consistency.engines.online_detection import LABEL_BYTES, IncrementalDetection
from pipeline.consistency.engines.online_history import (
    HISTORY,
    RETIRED_ENTRY_BYTES,
    HistoryCheck,
)
from pipeline.consistency.engines.online_weigh import Weighing
from pipeline.consistency.history import runs_by_robot
from pipeline.consistency.rules import DEFAULT_RESOLUTION, get_rule
from pipeline.errors import InputError, RobotsLost, processes_lost
from pipeline.progress import counted
from pipeline.types import Links

__all__ = ["Frame", "OnlineAssociation", "batch_resolve", "default_hold",
           "simulated_stage", "HISTORY"]

FRESH_LABELS = 1 << 40
"""First fresh label name: a set no retired frame anchors is named from here on."""

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


class OnlineAssociation(IncrementalDetection, Weighing, HistoryCheck):
    """The association of a team in motion, grown one step at a time (module docstring).

    Parameters
    ----------
    window : int >= 1 — steps of frames a robot holds
    resolution : a rule of :mod:`pipeline.consistency.rules`
    overturn : bool — the history repair may cut open links older than the step (default;
        step 3, :mod:`.online_history`), or only new links
    hold : int >= 0 or None — steps a frame stays in the stage (its links open) after it
        leaves the matching window; None: ``window - 1`` (module docstring, *Hold*)
    weigh : bool — every set the step's new links touch is weighed by the rule's merge
        (default; step 2b, :mod:`.online_weigh`), or only the conflictive ones (the earlier
        rule)
    gather : bool — the evidence rule's conflictive sets of at most ``B`` features are solved
        at their roots too, their bundles gathered as in step 2b (default; the same cuts), or
        by the rule's own flood to every robot of the set (step 2, :mod:`.online_detection`)
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
        ``stage_peak_bytes`` (the stage's peak over its images), and what robots lost
        during the stage cost (``stage_attempts``, ``images_lost``, ``cut_lost``,
        ``lost_messages``, ``lost_bytes``, ``lost_rounds``: :meth:`_stage_despite_losses`).

        Raises
        ------
        InputError
            A link breaks Assumptions 2.1–2.3, has no end in the step's frames or an end
            outside the window.
        RobotsLost
            An image lost by the stage again with none of its links left to cut
            (:meth:`_stage_despite_losses`).
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
                   stage_peak_bytes=0, history_bytes=0, stage_attempts=0, images_lost=[],
                   cut_lost=0, lost_messages=0, lost_bytes=0, lost_rounds=0)
        if self.robots_check and self.overturn:  # a step without new links has them too
            rec["history_rounds"] = 0
        if len(new_ids):
            self._stage_despite_losses(new_ids, t, rec)
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

    def _stage_despite_losses(self, new_ids: np.ndarray, t: int, rec: dict) -> None:
        """Steps 2 to 4 (:meth:`_stage`), again where the stage lost robots.

        A stage whose robots are processes may lose one (its process ends, its host goes
        down: the stage raises :class:`~pipeline.errors.RobotsLost` naming its images, and
        nothing of that stage is applied). A robot lost for the first time in the step is
        started again: the same stage runs again on the same inputs, so it decides as the
        undisturbed stage would. An image lost a second time in the step is given up for
        it: its links in the step's sub-problem (the step's new links and the kept window
        links of the sets they touch) are cut as ``robot-lost``, and the stage runs on what
        is left. A cut only splits sets, and the stage that then completes is a whole stage
        on the record's links: the guarantee of the step (module docstring) holds as
        without the loss. An image lost again with none of its links left in the sub-problem
        (it takes part through retired pieces only) stops the run
        (:class:`~pipeline.errors.RobotsLost`).

        ``rec`` gets ``stage_attempts`` (the stages started: 1 without a loss; the lost ones
        and the one that completed, if any link was left for it), ``images_lost`` (per lost
        attempt, the images it lost), ``cut_lost`` (links cut ``robot-lost``, counted in
        ``cut``) and the lost attempts' messages, bytes and rounds (``lost_messages``,
        ``lost_bytes``, ``lost_rounds``; counted in ``messages``, ``bytes`` and
        ``rounds``: they were spent) as the stage reports them (over Zenoh, a team is
        stopped as soon as a robot process of it ends without publishing: the traffic of
        its robots that had not published is not counted, :func:`pipeline.runs.transports.
        zenoh.online_stage`)."""
        L = self.links
        start = dict(rec)
        lost_log: list[list[int]] = []
        seen: set = set()
        spent = dict(messages=0, bytes=0, rounds=0)
        cut_lost, ran = 0, 0
        while True:
            try:
                if len(new_ids):
                    self._stage(new_ids, t, rec)
                    ran = 1
                break
            except RobotsLost as e:
                images = [int(self._stage_images[c]) for c in e.cameras]
                lost_log.append(images)
                for k in spent:
                    spent[k] += int(e.stats.get(k, 0))
                again = [g for g in images if g in seen]
                seen.update(images)
                rec.clear()
                rec.update(start)
                if not again:   # started again: the same stage on the same inputs
                    continue
                real = self._stage_real
                gone = real[np.isin(L.ci[real], again) | np.isin(L.cj[real], again)]
                gone = gone[L.kept[gone]]
                if not len(gone):  # (e names the image by its place in the sub-problem)
                    one = len(again) == 1
                    raise RobotsLost(f"{processes_lost(again)} twice during step {t}'s "
                                     f"consistency stage, with none of {'its' if one else 'their'} "
                                     "links left in the step's sub-problem to cut "
                                     f"({'it takes' if one else 'they take'} part through "
                                     "retired pieces only)",
                                     e.cameras, e.stats) from e
                self._cut(gone, "robot-lost", t)
                cut_lost += len(gone)
                new_ids = new_ids[L.kept[new_ids]]
        rec.update(stage_attempts=len(lost_log) + ran, images_lost=lost_log, cut_lost=cut_lost,
                   lost_messages=spent["messages"], lost_bytes=spent["bytes"],
                   lost_rounds=spent["rounds"])
        rec["cut"] += cut_lost
        rec["messages"] += spent["messages"]
        rec["bytes"] += spent["bytes"]
        rec["rounds"] += spent["rounds"]

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


def batch_resolve(features_per_image, links: Links, resolution: str = DEFAULT_RESOLUTION,
                  keypoints=None, projections=None):
    """The batch run the online stage is compared with: the same rule from scratch on all
    links so far (images as cameras, cameras sharing a link as neighbours)."""
    kw = {}
    if get_rule(resolution).needs_evidence:
        kw = dict(keypoints=keypoints, projections=projections)
    return resolve_conflicts(np.asarray(features_per_image, np.int64), None, links,
                             resolution=resolution, **kw)
