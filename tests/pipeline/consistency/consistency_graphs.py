"""Random association graphs that satisfy Assumptions 2.1–2.3, on random comm graphs."""

import numpy as np
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


@st.composite
def instances(draw, max_n=7, max_feat=4):
    n = draw(st.integers(2, max_n))
    max_f = draw(st.integers(1, max_feat))
    p_edge = draw(st.sampled_from([0.3, 0.6, 1.0]))
    p_link = draw(st.sampled_from([0.5, 0.8, 1.0]))
    seed = draw(st.integers(0, 2**32 - 1))
    return random_instance(np.random.default_rng(seed), n, max_f, p_edge, p_link)
