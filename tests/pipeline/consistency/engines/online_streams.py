"""Random streams of a team in motion for the online association's tests: frames per step
and links from each new frame into the window, with or without poses."""

import numpy as np
from hypothesis import strategies as st

from pipeline.consistency.engines.online import Frame
from pipeline.types import Links

__all__ = ["streams", "posed_streams", "camera", "project", "K"]


@st.composite
def streams(draw, max_robots=4, max_steps=6, max_m=4):
    """A team's stream: per step one frame per robot and random one-to-one links from each
    new frame to frames of the window (own earlier frames, others' frames, this step's)."""
    n = draw(st.integers(2, max_robots))
    steps = draw(st.integers(1, max_steps))
    window = draw(st.integers(1, 3))
    hold = draw(st.integers(0, 2))
    seed = draw(st.integers(0, 2**31 - 1))
    density = draw(st.sampled_from([0.3, 0.6, 0.9]))
    rng = np.random.default_rng(seed)
    m_all, step_of, robot_of, out = [], [], [], []
    for t in range(steps):
        frames = [Frame(i, int(rng.integers(1, max_m + 1))) for i in range(n)]
        first = len(m_all)
        for f in frames:
            m_all.append(f.m)
            step_of.append(t)
            robot_of.append(f.robot)
        ci, fi, cj, fj = [], [], [], []
        for g in range(first, len(m_all)):
            for h in range(len(m_all)):
                if h == g or step_of[h] <= t - window or (h >= first and h > g):
                    continue
                if rng.random() > density:
                    continue
                k = min(m_all[g], m_all[h])
                r = rng.permutation(m_all[g])[:k]
                s = rng.permutation(m_all[h])[:k]
                use = rng.random(k) < 0.7
                for a, b in zip(r[use], s[use], strict=True):
                    lo, hi = (h, g) if h < g else (g, h)
                    fa, fb = (b, a) if h < g else (a, b)
                    ci.append(lo), fi.append(int(fa)), cj.append(hi), fj.append(int(fb))
        q = rng.uniform(0.05, 0.95, len(ci))
        out.append((frames, Links(ci, fi, cj, fj, q)))
    return window, hold, out



K = np.array([[200.0, 0, 100], [0, 200.0, 100], [0, 0, 1]])


def camera(x: float) -> np.ndarray:
    """``K [I | -c]``: a camera at ``(x, 0, -6)`` looking along +z."""
    return K @ np.c_[np.eye(3), -np.array([x, 0.0, -6.0])]


def project(P, X):
    p = P @ np.r_[X, 1.0]
    return p[:2] / p[2]


@st.composite
def posed_streams(draw, max_robots=4, max_steps=4, max_m=4):
    """A team's stream with poses: robot ``i`` at step ``t`` is a camera at ``x = i + t / 4``;
    each feature sees one of a few 3D points (its keypoint that point's projection); a link
    joins two features of the same point (a good link) with probability ``p_good``, else any
    two features (mostly spurious: the geometric test refutes them)."""
    n = draw(st.integers(2, max_robots))
    steps = draw(st.integers(1, max_steps))
    window = draw(st.integers(1, 3))
    hold = draw(st.integers(0, 2))
    rng = np.random.default_rng(draw(st.integers(0, 2**31 - 1)))
    p_good = draw(st.sampled_from([0.5, 0.8, 1.0]))
    points = rng.uniform([-1, -1, 0], [4, 1, 2], (draw(st.integers(2, 6)), 3))
    pts, step_of, out = [], [], []
    for t in range(steps):
        frames, first = [], len(pts)
        for i in range(n):
            P = camera(i + t / 4)
            see = rng.integers(0, len(points), int(rng.integers(1, max_m + 1)))
            kp = np.array([project(P, points[k]) for k in see])
            frames.append(Frame(i, len(see), kp, P))
            pts.append(see)
            step_of.append(t)
        ci, fi, cj, fj = [], [], [], []
        for g in range(first, len(pts)):
            for h in range(g):
                if step_of[h] <= t - window or rng.random() < 0.3:
                    continue
                used_g, used_h = set(), set()
                for r in rng.permutation(len(pts[g])).tolist():
                    same = [s for s in range(len(pts[h])) if pts[h][s] == pts[g][r]]
                    pool = same if same and rng.random() < p_good else range(len(pts[h]))
                    free = [s for s in pool if s not in used_h]
                    if not free:
                        continue
                    s_ = int(rng.choice(free))
                    used_g.add(r)
                    used_h.add(s_)
                    ci.append(h), fi.append(s_), cj.append(g), fj.append(r)
        out.append((frames, Links(ci, fi, cj, fj, rng.uniform(0.05, 0.95, len(ci)))))
    return window, hold, out
