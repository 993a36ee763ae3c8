"""Step 2 of an online step: incremental detection, the rule's stage on what the new links touch.

The touched labels are the labels of the new links' ends (each robot knows them: the two
robots of a new link exchange their ends' labels, counted as one message of 16 bytes per
link). The stage runs on the *sub-problem*: the window
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
left to the real link in the detection and kept in the history check, step 3).

The methods of :class:`IncrementalDetection` are those of
:class:`~pipeline.consistency.engines.online.OnlineAssociation` for this step (the words
window, label, retired piece and border link are those of :mod:`.online`). They read the
record: the labels of the window features, the kept window links, the border links into the
retired pieces, the images' keypoints and projections. They build the sub-problem and its
history links, call the record's ``stage`` on it, cut the links the rule cuts and write the
stage's figures into the step's record; then step 2b weighs the sub-problem's sets
(:mod:`.online_weigh`) and steps 3 and 4 check them against the retired pieces and name them
(:mod:`.online_history`).
"""

from __future__ import annotations

import numpy as np

from pipeline.types import Links

__all__ = ["IncrementalDetection", "LABEL_BYTES", "WEIGHED_RULE"]

WEIGHED_RULE = "evidence"
"""The rule whose merge weighs the conflict-free sets of a step (step 2b, :mod:`.online_weigh`):
its stage cuts only in conflictive sets of at most ``B`` features (and merges the larger
ones); ``sync`` merges every set already, ``paper``'s Alg. 1 has no weights."""

LABEL_BYTES = 8
"""Bytes of one label on the wire (int64)."""


class IncrementalDetection:
    """Step 2 of :meth:`.online.OnlineAssociation.add_step` (module docstring)."""

    def _stage(self, new_ids: np.ndarray, t: int, rec: dict) -> None:
        """Steps 2 to 4 of step ``t`` on what its new links ``new_ids`` touch; the step's
        figures go into ``rec``."""
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
        self._stage_images, self._stage_real = images, real  # read where the stage loses robots
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

    def _local_links(self, images, a, b, q) -> Links:
        img_a = np.searchsorted(self.offset, a, side="right") - 1
        img_b = np.searchsorted(self.offset, b, side="right") - 1
        ca, cb = np.searchsorted(images, img_a), np.searchsorted(images, img_b)
        fa, fb = a - self.offset[img_a], b - self.offset[img_b]
        swap = ca > cb
        return Links(np.where(swap, cb, ca), np.where(swap, fb, fa), np.where(swap, ca, cb),
                     np.where(swap, fa, fb), q)


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


def _duplicated_keys(group: np.ndarray, item: np.ndarray) -> list[int]:
    """Groups holding one item twice."""
    if not len(group):
        return []
    key = np.stack([group, item], axis=1)
    u, counts = np.unique(key, axis=0, return_counts=True)
    return np.unique(u[counts > 1, 0]).tolist()

