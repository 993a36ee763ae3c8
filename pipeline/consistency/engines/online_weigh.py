"""Step 2b of an online step: the rule's merge weighs the sets the detection found conflict-free.

*Weighing the conflict-free sets* (``weigh``, default; the evidence rule,
:data:`~.online_detection.WEIGHED_RULE`). The rule cuts only in the sets it finds
conflictive (its sets of at most ``B`` features, the bundle budget; a larger set gets its
``sync`` merge, and is left to it here); every other set of the sub-problem, one the step's new links touched
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

The method ``_weigh`` of :class:`Weighing` is that of
:class:`~pipeline.consistency.engines.online.OnlineAssociation` for this step; step 2
(:mod:`.online_detection`) calls it after the rule. It reads the step's sub-problem (its
features, images, real and history links, the sets they formed before the rule's cuts) and
the images' keypoints and projections; it solves the sets at their roots
(:func:`.gather.solve_at_roots`), or takes the cuts the stage's robots made
(``robots_solve``), cuts the links the solution cuts and writes the weighing's figures into
the step's record.
"""

from __future__ import annotations

import numpy as np

from pipeline.consistency.engines.gather import solve_at_roots
from pipeline.consistency.engines.online_detection import _duplicated_keys

__all__ = ["Weighing"]


class Weighing:
    """Step 2b of :meth:`.online.OnlineAssociation.add_step` (module docstring)."""

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
