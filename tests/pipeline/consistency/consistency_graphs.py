"""Random association graphs that satisfy Assumptions 2.1–2.3, on random comm graphs.

:func:`instances` plants conflictive sets (chains of matches through several cameras that
join two features of one camera) in most examples, so that the properties it feeds test the
detection and the resolution and not only the empty case; :func:`conflict_share` is what
``test_consistency_graphs`` checks of it.
"""

import numpy as np
from hypothesis import event
from hypothesis import strategies as st

from pipeline.types import Links


def random_instance(rng: np.random.Generator, n: int, max_feat: int, p_edge: float,
                    p_link: float):
    """Features per camera, comm edges (E, 2) and one-to-one links on comm edges only."""
    fpc = rng.integers(1, max_feat + 1, size=n)
    iu, ju = np.triu_indices(n, k=1)
    on = rng.random(iu.size) < p_edge
    edges = np.stack([iu[on], ju[on]], axis=1)
    ci, fi, cj, fj = [], [], [], []
    for i, j in edges:
        k = int(min(fpc[i], fpc[j]))
        r = rng.permutation(fpc[i])[:k]
        s = rng.permutation(fpc[j])[:k]
        keep = rng.random(k) < p_link  # one-to-one partial matching A_ij (Assumption 2.2)
        ci += [i] * int(keep.sum())
        cj += [j] * int(keep.sum())
        fi += r[keep].tolist()
        fj += s[keep].tolist()
    return fpc, edges, Links(ci, fi, cj, fj, rng.random(len(ci)))


def plant_conflicts(rng: np.random.Generator, fpc, edges, links: Links, count: int):
    """Add ``count`` chains ``(c, f0) - (c1, x1) - … - (ck, xk) - (c, f1)``, ``f0 != f1``,
    through ``k = 2…4`` other cameras: each joins two features of camera ``c``.

    A chain follows a match that already leaves a feature for the next camera, else reuses a
    feature not yet matched to the previous camera, else adds a new feature; the result is
    one-to-one (Assumption 2.2) and every new link lies on a comm edge (added if missing).
    A chain whose existing matches close back on ``f0`` joins nothing and is drawn again
    (at most ``4 count`` chains in all).
    """
    n = len(fpc)
    fpc = np.array(fpc, dtype=np.int64)
    partner = {}  # (camera, feature, other camera) -> the other camera's feature
    rows = list(zip(links.cam_i.tolist(), links.feat_i.tolist(), links.cam_j.tolist(),
                    links.feat_j.tolist(), links.quality.tolist(), strict=True))
    for i, r, j, s, _ in rows:
        partner[i, r, j], partner[j, s, i] = s, r

    def link(ci, x, cj, y):
        partner[ci, x, cj], partner[cj, y, ci] = y, x
        (a, u), (b, v) = sorted([(ci, x), (cj, y)])
        rows.append((a, u, b, v, float(rng.random())))

    def free_feature(cam, other, exclude=-1):
        """A feature of ``cam`` not matched to camera ``other``: an existing one with
        probability 3/4 where there is one, else a new one."""
        free = [x for x in range(fpc[cam]) if (cam, x, other) not in partner and x != exclude]
        if free and rng.random() < 0.75:
            return int(rng.choice(free))
        fpc[cam] += 1
        return int(fpc[cam] - 1)

    planted = 0
    for _ in range(4 * count):
        if planted == count or n < 3:
            break
        k = int(rng.integers(2, min(n - 1, 4) + 1))
        c, *path = rng.choice(n, size=k + 1, replace=False).tolist()
        f0 = int(rng.integers(fpc[c] + 1))  # fpc[c]: a new feature
        fpc[c] = max(fpc[c], f0 + 1)
        cam, x = c, f0
        for nxt in path:
            y = partner.get((cam, x, nxt))
            if y is None:
                y = free_feature(nxt, cam)
                link(cam, x, nxt, y)
            cam, x = nxt, y
        f1 = partner.get((cam, x, c))
        if f1 is None:
            f1 = free_feature(c, cam, exclude=f0)
            link(cam, x, c, f1)
        planted += f1 != f0
    ci, fi, cj, fj, q = (list(col) for col in zip(*rows, strict=True)) if rows else [[]] * 5
    pairs = {tuple(e) for e in np.asarray(edges, dtype=np.int64).reshape(-1, 2).tolist()}
    pairs |= set(zip(ci, cj, strict=True))
    edges = np.array(sorted(pairs), dtype=np.int64).reshape(-1, 2)
    return fpc, edges, Links(ci, fi, cj, fj, q)


def conflictive_sets(fpc, links: Links) -> int:
    """Number of association sets holding two features of one camera (Def. 2.4), by a plain
    union-find of its own (independent of :mod:`pipeline.consistency.centralized`)."""
    parent: dict = {}

    def find(x):
        while parent.setdefault(x, x) != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    for i, r, j, s in zip(links.cam_i.tolist(), links.feat_i.tolist(), links.cam_j.tolist(),
                          links.feat_j.tolist(), strict=True):
        parent[find((i, r))] = find((j, s))
    seen, conflictive = set(), set()
    for cam, feat in parent:
        root = find((cam, feat))
        if (root, cam) in seen:
            conflictive.add(root)
        seen.add((root, cam))
    return len(conflictive)


def conflict_share(fpc, links: Links) -> str:
    """The class of an example for :func:`hypothesis.event`: no link, no conflictive set, or
    some."""
    if len(links) == 0:
        return "no link"
    return "conflictive set(s)" if conflictive_sets(fpc, links) else "no conflictive set"


@st.composite
def instances(draw, max_n=7, max_feat=4):
    """``(features per camera, comm edges, links)``: planted conflicts (1–3 chains, 3 cameras
    or more) in about 4 examples of 5; the rest are plain :func:`random_instance` draws."""
    planted = draw(st.sampled_from([0, 1, 1, 2, 3]))
    n = draw(st.integers(3 if planted else 2, max(max_n, 3)))  # a conflict needs 3 cameras
    max_f = draw(st.integers(1, max_feat))
    p_edge = draw(st.sampled_from([0.3, 0.6, 1.0]))
    p_link = draw(st.sampled_from([0.5, 0.8, 1.0]))
    seed = draw(st.integers(0, 2**32 - 1))
    fpc, edges, links = random_instance(np.random.default_rng(seed), n, max_f, p_edge, p_link)
    if planted:
        fpc, edges, links = plant_conflicts(np.random.default_rng([seed, 1]), fpc, edges, links,
                                            planted)
    event(conflict_share(fpc, links))
    return fpc, edges, links
