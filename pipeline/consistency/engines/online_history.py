"""Steps 3 and 4 of an online step: the history check and repair, then the sets' fresh labels.

*History check.* A set the new links formed may join two retired pieces that hold one retired
image (two features of one retired frame), which the window alone cannot show.
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

Step 4: every set of the sub-problem gets a fresh label.

The methods of :class:`HistoryCheck` are those of
:class:`~pipeline.consistency.engines.online.OnlineAssociation` for these steps: step 2
(:mod:`.online_detection`) calls ``_history_check`` after the rule and the weighing, and
``_history_inputs`` for the robots' check. They read the sub-problem after the rule's cuts,
the border links and the retired entries of the pieces it reaches; they cut the links the
repair skips (reason :data:`HISTORY`), drop the pieces no border link reaches any more and
give every set of the sub-problem a fresh label. That the repair leaves every set
conflict-free is part of the guarantee proved in :mod:`.online`.
"""

from __future__ import annotations

import numpy as np

from pipeline.consistency.engines.online_detection import LABEL_BYTES, _chain, _duplicated_keys
from pipeline.consistency.history import overlapping_runs, rebuild
from pipeline.types import Links

__all__ = ["HistoryCheck", "HISTORY", "RETIRED_ENTRY_BYTES", "FLOOD_LINK_BYTES"]

HISTORY = "history"
"""Reason of a link cut by the history repair (step 3 of the module docstring)."""
RETIRED_ENTRY_BYTES = 16
"""Bytes of one retired entry, held or flooded: a piece name (int64) and a run of steps
(two int32; the robot is the holder)."""
FLOOD_LINK_BYTES = 24
"""Bytes of one link in the history flood (two global feature ids and a float32 quality)."""


class HistoryCheck:
    """Steps 3 and 4 of :meth:`.online.OnlineAssociation.add_step` (module docstring)."""

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
