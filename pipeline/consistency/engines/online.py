"""Online association: frames arrive step by step and the kept association stays conflict-free.

The papers take one snapshot (all images, one association). Here a team in motion adds one
frame per robot per step; :class:`OnlineAssociation` keeps every link ever made (kept or
cut, with the step that made and the step that cut it) and runs the distributed stage of
Aragüés et al. only on what the step's new links touch.

Words
-----
*Image* (a camera of the papers, Def. 2.4): one frame of one robot; a conflict is two
features of one image in one association set. *Window*: a robot holds the frames of its last
``W`` steps (``window``); at step ``t`` the frames of steps ``t - W + 1 .. t`` are in the
window, older frames are *retired*: their features and links are final (a retired link is
never cut again). New links must join a frame of step ``t`` to a frame in the window
(the runner matches a new frame against its robot's ``W - 1`` previous frames and its current
neighbours' last ``W`` frames). *Label*: every feature carries the name of its track (a new
feature starts as its own global id; a set keeps the name of the track whose retired frames
it holds, otherwise it gets a fresh name, :data:`FRESH_LABELS`). A label names a set of
features that contains the feature's true association set: a window feature with a kept
link into a retired frame is *anchored*, and the anchored window pieces of one label are
treated as one set (they may be joined through retired frames; if they are not, treating
them as joined only makes the checks below stricter). Every robot holds, for each label it
carries, the retired images of its own retired frames in that label (``retired`` entries):
8 bytes per (label, image), dropped once the label has no feature left in any window.

One step (:meth:`OnlineAssociation.add_step`)
---------------------------------------------
1. The step's frames join the window, frames older than ``W`` steps retire.
2. *Incremental detection.* The touched labels are the labels of the new links' ends (each
   robot knows them: the two robots of a new link exchange their ends' labels, counted as
   one message of 16 bytes per link). The stage runs on the *sub-problem*: the window features of the touched labels and
   the step's new features, the kept window links among them, the new links, and one
   *history link* between consecutive anchored window pieces of a label that the window
   links do not join (the pieces may be joined through retired frames; the history link
   carries that connection, so a set that closes through history is one set for the
   detection). On it
   the simulator runs Aragüés et al.'s detection (Sec. III, Prop. 3.5) and the rule of
   :mod:`pipeline.consistency.rules` (default :data:`~pipeline.consistency.rules.DEFAULT_RESOLUTION`)
   until conflict-free (Prop. 4.5), images as its cameras; a cut of a history link is
   ignored (it is no link of the association).
3. *History check.* A set the new links formed may merge two labels that share a retired
   image (two features of one retired frame), which the window alone cannot show. Every
   member of a set knows the set after the detection (Prop. 3.5: its row is the whole set);
   the set's robots flood their retired entries of the set's labels and its new links (the
   same flood as the evidence rule, counted as 8 bytes per entry and 24 per link, per robot
   of the set, in the detection's rounds), and each solves the same deterministic repair:
   start from the set's kept old links and history links (each label alone is
   conflict-free), add the kept new links by decreasing quality, skip one that would put two
   features of one image (window or retired) in one set. A skipped link is cut with reason
   ``history``. So new evidence never overturns a retired frame's decision.
4. Labels are renamed: a final set holding anchored features takes the smallest of their
   labels (their retired entries follow it); any other set gets a fresh name.

Earlier decisions: a cut link is never restored. A kept link is cut only at a step whose new
links make its set conflictive, and only by the rule (reason of the rule) or by the history
repair; every other kept link keeps its decision, and the labels of untouched tracks do not
change.

Guarantee (after every step the kept association is conflict-free), by induction on the
steps. Before the first step there is no link. Suppose every label holds at most one
feature of every image after step ``t - 1``. At step ``t`` only sets reached by a new link
can change: a set no new link reaches keeps its links (the stage runs on touched labels
only; cuts happen only in the sub-problem), so it stays conflict-free. A set the new links
reach is, after the step, contained in one component of the sub-problem's kept links plus
history links, together with the retired parts of its labels (a retired feature is joined to
the window only through its label's window features, whose pieces the history links join).
The rule leaves every component of the sub-problem conflict-free over window images
(Prop. 4.5 for Alg. 1; one pass of the evidence rule). If the rule cut a history link (which
stays), or the labels merged in a component share a retired image, the repair rebuilds the
component from conflict-free pieces and adds a link only when the two pieces have no image
in common (window or retired): the result is conflict-free. Hence a conflict created by new
links is always found: it lies in a set that contains a new link, whose labels are touched,
so it is inside the sub-problem (window images, caught by detection, Prop. 3.5) or in the
retired entries of its labels (caught by the history check).

What each robot knows after a step: for each of its window features, its label (its set's
name) and, from the detection, the members of its set within the window; for each label it
carries, its own retired images in it; every link it holds, kept or cut, with the step.

Costs: rounds, messages and bytes are the simulator's counts of the sub-problem's stage
(images are its cameras, so messages between two frames of one robot are counted as if
sent: an upper bound on what goes over the air), plus the label exchange of the new links
and the history flood. The bookkeeping of this class (arrays of all links and features) is
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
from pipeline.consistency.rules import DEFAULT_RESOLUTION, get_rule
from pipeline.errors import InputError
from pipeline.types import Links

__all__ = ["Frame", "OnlineAssociation", "batch_resolve", "HISTORY", "LABEL_BYTES",
           "RETIRED_ENTRY_BYTES", "FLOOD_LINK_BYTES"]

FRESH_LABELS = 1 << 40
"""First fresh label name: a set no retired frame anchors is named from here on."""

HISTORY = "history"
"""Reason of a link cut by the history repair (step 3 of the module docstring)."""

LABEL_BYTES = 8
"""Bytes of one label on the wire (int64)."""
RETIRED_ENTRY_BYTES = 8
"""Bytes of one retired entry in the history flood (an image id; the label is the set's)."""
FLOOD_LINK_BYTES = 24
"""Bytes of one link in the history flood (two global feature ids and a float32 quality)."""


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

    def __init__(self, window: int, resolution: str = DEFAULT_RESOLUTION):
        if isinstance(window, bool) or not isinstance(window, (int, np.integer)) or window < 1:
            raise InputError(f"window {window!r}: expected a number of steps >= 1")
        self.window = int(window)
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
        self.border = np.zeros(0, np.int64)     # kept links into retired frames per feature
        self._fresh = FRESH_LABELS              # next fresh label name
        self.links = _LinkTable()
        self.window_images = np.zeros(0, np.int64)
        self.window_links = np.zeros(0, np.int64)  # ids of links with both ends in the window
        self.ret_label = np.zeros(0, np.int64)
        self.ret_image = np.zeros(0, np.int64)
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
        bytes each: two ids, two features, quality) and its retired entries (16 bytes each:
        label and image). Descriptors are the matcher's, counted by the caller."""
        n = int(self.robot.max()) + 1 if len(self.robot) else 0
        out = np.zeros(n, np.int64)
        w = self.window_images
        np.add.at(out, self.robot[w], 16 * self.m[w])
        wl = self.window_links
        np.add.at(out, self.robot[self.links.ci[wl]], 40)
        np.add.at(out, self.robot[self.links.cj[wl]], 40)
        np.add.at(out, self.robot[self.ret_image], 16)
        return out

    # ---------------------------------------------------------------- one step
    def add_step(self, frames: list[Frame], links: Links) -> dict:
        """Add a step's frames and new links, run the stage on what they touch.

        ``frames`` get the image ids ``n_images, n_images + 1, ...`` in their order; ``links``
        use those ids (cameras = images). Returns the step's record (also appended to
        :attr:`steps`): ``step``, ``links_new``, ``touched_labels``, ``sub_images``,
        ``sub_features``, ``sub_links``, ``history_links``, ``conflictive_features``
        (found by the step's first detection), ``conflictive_sets`` (resolved by the rule),
        ``cut`` (``cut_rule``, ``cut_history``, ``cut_old``: of them, links made at an
        earlier step), ``rounds`` (detection + resolution rounds), ``messages``, ``bytes``,
        ``wall_s``, ``robot_state_bytes_max``, ``stage_peak_bytes`` (the stage's peak over
        its images).

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
        self._retire(t)
        new_ids = self._add_links(links, first, t)
        rec = dict(step=t, frames=len(frames), links_new=int(len(new_ids)), touched_labels=0,
                   sub_images=0, sub_features=0, sub_links=0, history_links=0,
                   conflictive_features=0, conflictive_sets=0, cut=0, cut_rule=0,
                   cut_history=0, cut_old=0, rounds=0, detection_rounds=0,
                   resolution_rounds=0, messages=0, bytes=0, stage_peak_bytes=0)
        if len(new_ids):
            self._stage(new_ids, t, rec)
        self._drop_dead_labels()
        rec["robot_state_bytes_max"] = int(self.robot_state_bytes().max(initial=0))
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
            self.border = np.concatenate([self.border, np.zeros(m, np.int64)])
            self.window_images = np.append(self.window_images, g)

    def _retire(self, t: int) -> None:
        old = self.window_images[self.step[self.window_images] <= t - self.window]
        if not len(old):
            return
        feats = np.concatenate([self.offset[g] + np.arange(self.m[g]) for g in old])
        imgs = np.repeat(old, self.m[old])
        tracked = self.degree[feats] > 0
        self.ret_label = np.concatenate([self.ret_label, self.label[feats[tracked]]])
        self.ret_image = np.concatenate([self.ret_image, imgs[tracked]])
        self.window_images = np.setdiff1d(self.window_images, old)
        L = self.links
        wl = self.window_links
        gone_i, gone_j = np.isin(L.ci[wl], old), np.isin(L.cj[wl], old)
        # a kept link from a window feature into a retired frame anchors that feature
        a, b = self._ends(wl)
        border = L.kept[wl] & (gone_i != gone_j)
        np.add.at(self.border, np.where(gone_i, b, a)[border], 1)
        self.window_links = wl[~(gone_i | gone_j)]

    def _add_links(self, links: Links, first: int, t: int) -> np.ndarray:
        from pipeline.association import check_links

        check_links(links, self.m)
        new_img = (links.cam_i >= first) | (links.cam_j >= first)
        in_window = np.isin(links.cam_i, self.window_images) & \
            np.isin(links.cam_j, self.window_images)
        bad = np.flatnonzero(~new_img | ~in_window)
        if bad.size:
            k = bad[0]
            raise InputError(f"new link {k} ({links.cam_i[k]},{links.feat_i[k]})-"
                             f"({links.cam_j[k]},{links.feat_j[k]}): a new link joins a frame of "
                             f"this step to a frame in the window of {self.window} steps")
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
        a_w, b_w = self._ends(wl)
        old_ids = wl[L.kept[wl] & (L.step_added[wl] < t) & np.isin(self.label[a_w], touched)]
        a_o, b_o = self._ends(old_ids)
        # history links: consecutive window pieces of a label (joined through retired frames)
        piece = self._components(sub, a_o, b_o)
        anch = _anchored(self.label[sub], piece, self.border[sub] > 0)
        hist_a, hist_b = _history_links(sub[anch], self.label[sub][anch], piece[anch])
        real = np.concatenate([old_ids, new_ids])
        a_r, b_r = self._ends(real)
        a_all = np.concatenate([a_r, hist_a])
        b_all = np.concatenate([b_r, hist_b])
        q_all = np.concatenate([L.quality[real], np.ones(len(hist_a))])
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
        res = resolve_conflicts(self.m[images], None, local_links,
                                resolution=self.resolution, **kw)
        st = res.stats
        first = st["per_iteration"][0] if st["per_iteration"] else {}
        rec.update(conflictive_features=int(first.get("conflictive_features", 0)),
                   conflictive_sets=int(sum(p.get("conflictive_sets", 0)
                                            for p in st["per_iteration"])),
                   detection_rounds=int(st["detection_rounds"]),
                   resolution_rounds=int(st["resolution_rounds"]),
                   messages=int(st["messages"]), bytes=int(st["bytes"]),
                   stage_peak_bytes=int(st["max_robot_memory_bytes"]))
        rec["bytes"] += 2 * LABEL_BYTES * len(new_ids)
        rec["messages"] += len(new_ids)  # counted as one message per link (both labels)
        cut = np.flatnonzero(res.deleted[:n_real])
        self._cut(real[cut], str(self.rule.name), t)
        rec["cut_rule"] = int(len(cut))
        # history check and repair (step 3), then the new labels (step 4)
        hist_cut, flood = self._history_check(sub, real, t)
        rec["cut_history"] = int(hist_cut)
        rec["bytes"] += int(flood)
        rec["rounds"] = rec["detection_rounds"] + rec["resolution_rounds"]
        rec["cut"] = rec["cut_rule"] + rec["cut_history"]
        rec["cut_old"] = int(((L.step_cut == t) & (L.step_added < t)).sum())

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
        """Cut kept links ``ids`` at the current step for a later stage's ``reason`` (e.g.
        ``fusion-outlier``). Cutting only splits sets: the association stays conflict-free."""
        self._cut(np.asarray(ids, np.int64).reshape(-1), reason, self.t)

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
        return connected_components(adj, directed=False)[1]

    def _history_check(self, sub, real, t: int) -> tuple[int, int]:
        """Step 3 of the module docstring: returns (links cut, flood bytes).

        After the rule's cuts a label's window features fall into *pieces* (components of
        the kept window links). A piece holding a feature with a kept link into a retired
        frame is *anchored*: the check joins the anchored pieces of a label (``hist_a``,
        ``hist_b``: each anchored feature to the label's smallest anchored feature), since
        they may be joined through retired frames, which only makes the check stricter. A
        piece with no such link is joined to the rest of its label by no link at all: it
        is a set of its own (exact)."""
        L = self.links
        old_label = self.label[sub]
        kept_real = real[L.kept[real]]
        a_k, b_k = self._ends(kept_real)
        anch = _anchored(old_label, self._components(sub, a_k, b_k), self.border[sub] > 0)
        hist_a, hist_b = _label_links(sub[anch], old_label[anch])
        comp = self._components(sub, np.concatenate([a_k, hist_a]),
                                np.concatenate([b_k, hist_b]))
        img_of = np.searchsorted(self.offset, sub, side="right") - 1
        # the retired entries of a label go with its anchored features (one component)
        lab_u, lab_first = np.unique(old_label[anch], return_index=True)
        comp_of_label = comp[anch][lab_first]
        on = np.isin(self.ret_label, lab_u)
        r_comp = comp_of_label[np.searchsorted(lab_u, self.ret_label[on])]
        r_img = self.ret_image[on]
        bad = set(_duplicated_keys(comp, img_of)) | set(_duplicated_keys(r_comp, r_img))
        cut_n, flood = 0, 0
        for c in sorted(bad):
            members = np.flatnonzero(comp == c)
            robots = np.unique(self.robot[img_of[members]])
            in_c = np.isin(self.offset[L.ci[kept_real]] + L.fi[kept_real], sub[members])
            links_c = kept_real[in_c]
            labels_c = np.unique(old_label[members][anch[members]])
            entries = int(np.isin(self.ret_label, labels_c).sum())
            flood += len(robots) * (RETIRED_ENTRY_BYTES * entries +
                                    FLOOD_LINK_BYTES * int((L.step_added[links_c] == t).sum()))
            skipped = self._repair(sub, members, links_c, hist_a, hist_b, img_of, old_label,
                                   anch, t)
            self._cut(skipped, HISTORY, t)
            cut_n += len(skipped)
        if bad:
            kept_real = real[L.kept[real]]
            a_k, b_k = self._ends(kept_real)
            comp = self._components(sub, np.concatenate([a_k, hist_a]),
                                    np.concatenate([b_k, hist_b]))
            comp_of_label = comp[anch][lab_first]
        # step 4: a set holding anchored features keeps the smallest of their labels (its
        # retired entries follow); any other set gets a fresh name
        has = np.zeros(comp.max() + 1 if len(comp) else 0, bool)
        has[comp[anch]] = True
        name = np.full(len(has), -1, np.int64)
        order = np.lexsort((old_label[anch], comp[anch]))
        ca, la = comp[anch][order], old_label[anch][order]
        first = np.r_[True, ca[1:] != ca[:-1]] if len(ca) else np.zeros(0, bool)
        name[ca[first]] = la[first]
        fresh = np.flatnonzero(~has)
        name[fresh] = self._fresh + np.arange(len(fresh))
        self._fresh += len(fresh)
        self.label[sub] = name[comp]
        keep = ~np.isin(self.ret_label, old_label) | np.isin(self.ret_label, lab_u)
        mapping = dict(zip(lab_u.tolist(), name[comp_of_label].tolist(), strict=True))
        self.ret_label, self.ret_image = self.ret_label[keep], self.ret_image[keep]
        on = np.isin(self.ret_label, lab_u)
        self.ret_label[on] = [mapping[x] for x in self.ret_label[on].tolist()]
        return cut_n, flood

    def _repair(self, sub, members, links_c, hist_a, hist_b, img_of, old_label, anch,
                t) -> np.ndarray:
        """The deterministic repair of one set (step 3): the new links it skips."""
        L = self.links
        parent = {int(f): int(f) for f in sub[members]}
        images: dict[int, set] = {int(f): {int(img_of[k])} for k, f in zip(members, sub[members],
                                                                            strict=True)}
        am = members[anch[members]]
        for lab in np.unique(old_label[am]).tolist():
            rets = self.ret_image[self.ret_label == lab].tolist()
            f0 = int(sub[am][old_label[am] == lab][0])
            images[f0] |= set(rets)

        def find(x):
            while parent[x] != x:
                parent[x] = parent[parent[x]]
                x = parent[x]
            return x

        def union(x, y) -> bool:
            rx, ry = find(x), find(y)
            if rx == ry:
                return True
            if images[rx] & images[ry]:
                return False
            if len(images[rx]) < len(images[ry]):
                rx, ry = ry, rx
            parent[ry] = rx
            images[rx] |= images[ry]
            return True

        is_new = L.step_added[links_c] == t
        old, new = links_c[~is_new], links_c[is_new]
        a_o, b_o = self._ends(old)
        mem = set(parent)
        base = [(int(x), int(y)) for x, y in zip(a_o, b_o, strict=True)]
        base += [(int(x), int(y)) for x, y in zip(hist_a, hist_b, strict=True)
                 if int(x) in mem]
        for x, y in base:  # pieces of one label: conflict-free by the induction
            union(x, y)
        new = new[np.lexsort((new, -L.quality[new]))]
        a_n, b_n = self._ends(new)
        skipped = [int(k) for k, x, y in zip(new, a_n, b_n, strict=True)
                   if not union(int(x), int(y))]
        return np.asarray(skipped, np.int64)

    def _drop_dead_labels(self) -> None:
        w = self.window_images
        if not len(self.ret_label):
            return
        wfeat = np.concatenate([self.offset[g] + np.arange(self.m[g]) for g in w]) if len(w) \
            else np.zeros(0, np.int64)
        live = np.isin(self.ret_label, self.label[wfeat])
        self.ret_label, self.ret_image = self.ret_label[live], self.ret_image[live]


def _history_links(sub: np.ndarray, label: np.ndarray, piece: np.ndarray):
    """Links joining, for every label, the pieces that hold it: one link between the smallest
    features of that label in consecutive pieces (a piece may hold several labels once new
    links join them)."""
    if not len(sub):
        z = np.zeros(0, np.int64)
        return z, z
    order = np.lexsort((sub, piece, label))
    lab, pc, f = label[order], piece[order], sub[order]
    first = np.r_[True, (lab[1:] != lab[:-1]) | (pc[1:] != pc[:-1])]
    lab, f = lab[first], f[first]            # smallest feature of each (label, piece)
    same = lab[1:] == lab[:-1]
    return f[:-1][same], f[1:][same]


def _anchored(label: np.ndarray, piece: np.ndarray, border: np.ndarray) -> np.ndarray:
    """Features whose piece holds a feature of their label with a link into a retired frame."""
    if not len(label):
        return np.zeros(0, bool)
    key = np.stack([label, piece], axis=1)
    u, inv = np.unique(key, axis=0, return_inverse=True)
    hit = np.zeros(len(u), bool)
    hit[inv.reshape(-1)[border]] = True
    return hit[inv.reshape(-1)]


def _label_links(sub: np.ndarray, label: np.ndarray):
    """Links joining every feature to the smallest feature of its label, ``(a, b)``."""
    if not len(sub):
        z = np.zeros(0, np.int64)
        return z, z
    order = np.lexsort((sub, label))
    lab, f = label[order], sub[order]
    first = np.r_[True, lab[1:] != lab[:-1]]
    root = f[first][np.cumsum(first) - 1]
    return root[~first], f[~first]


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
