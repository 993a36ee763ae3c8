"""One cycle through many cameras: one conflictive set as long as the team (a hostile input
that once took minutes); the stage must cut one link where Alg. 1's two waves meet."""

import numpy as np

from pipeline.consistency import resolve_conflicts
from pipeline.consistency.centralized import is_conflict_free
from pipeline.types import Links


def cycle(n: int):
    """Camera ``i`` linked to ``i + 1`` by feature 0; the last camera back to camera 0 by its
    feature 1: one association set holding two features of camera 0."""
    i = np.arange(n - 1)
    links = Links(np.r_[i, 0], np.r_[np.zeros(n - 1, int), 1], np.r_[i + 1, n - 1],
                  np.zeros(n, int))
    fpc = np.ones(n, dtype=np.int64)
    fpc[0] = 2
    return fpc, links


def test_cycle_through_1000_cameras_is_cut_once_where_the_waves_meet():
    n = 1000
    fpc, links = cycle(n)
    res = resolve_conflicts(fpc, None, links, resolution="paper")
    assert is_conflict_free(fpc, res.kept())
    assert res.deleted.sum() == 1 and res.reason[res.deleted].tolist() == ["resolution"]
    # root: camera 0 (two features of the set, eq. 10); its components C_(0,0) and C_(0,1)
    # travel both ways round the cycle and meet half-way (Thm. 4.3: at most n rounds)
    cut = int(np.flatnonzero(res.deleted)[0])
    assert {int(links.cam_i[cut]), int(links.cam_j[cut])} in ({n // 2 - 1, n // 2},
                                                                {n // 2, n // 2 + 1})
    st = res.stats
    assert st["per_iteration"][0]["detection_rounds"] == n + 1  # d + 1 (Cor. 3.6), d = n
    assert st["iterations"] == 1 and st["resolution_rounds"] <= n + 1
