"""The online weighing (pipeline.consistency.engines.online_weigh) at its limits: a
conflict-free set of exactly ``B`` features is the rule's to leave alone, so the weighing
solves it; a history link the solution refutes is not cut (it stands for a retired piece)."""

import numpy as np
from online_streams import camera, project
from test_online_record import _spurious_step

from pipeline.consistency.engines.online import Frame, OnlineAssociation
from pipeline.types import Links


def test_a_set_of_exactly_the_bundle_budget_is_weighed(monkeypatch):
    """Three posed cameras, one feature each: 0 and 1 see X, 2 sees Y, all three linked. With
    ``B = 3`` the set is not large: the rule leaves it (conflict-free), the weighing cuts
    the two links to camera 2."""
    from pipeline.consistency import setlists

    monkeypatch.setattr(setlists, "SET_BUNDLE_BYTES", 3 * setlists.bundle_bytes_bound(3))
    rec, st, oa = _spurious_step(weigh=True)
    assert st["bundle_budget"] == 3 and st["large_sets"] == 0
    assert rec["weighed_sets"] == 1 and rec["cut_weigh"] == 2
    assert oa.links.kept.tolist() == [True, False, False]


def test_a_history_link_the_weighing_refutes_is_ignored(monkeypatch):
    """Window 2, hold 0. Step 1 links frames 2 (robot 0, sees X) and 3 (robot 1, sees Y) to
    frame 0 (unposed: not weighed); step 2 retires frame 0, so a history link joins 2 and 3
    through its piece, and links 4 (sees X) to 2 and 5 (sees X) to 4. The solution merges
    2, 4, 5 and refutes the history link (Y is not X): nothing is cut, the history link
    being the piece's, and the set keeps one label."""
    from pipeline.consistency.engines import online_weigh

    X, Y = np.array([0.5, 0.2, 1.0]), np.array([1.5, -0.4, 0.5])
    P = [camera(x) for x in (0.0, 0.5, 1.0, 1.5, 2.0, 2.5)]

    def frame(g, robot, point, posed=True):
        return Frame(robot, 1, project(P[g], point)[None], P[g] if posed else None)

    solved = []

    def spy(*args, **kw):
        sol = solve_at_roots(*args, **kw)
        solved.append(sol.cut.tolist())
        return sol

    solve_at_roots = online_weigh.solve_at_roots
    monkeypatch.setattr(online_weigh, "solve_at_roots", spy)
    oa = OnlineAssociation(window=2, hold=0, robots_check=False)
    oa.add_step([frame(0, 0, X, posed=False), frame(1, 1, X)], Links([], [], [], []))
    oa.add_step([frame(2, 0, X), frame(3, 1, Y)], Links([0, 0], [0, 0], [2, 3], [0, 0],
                                                        [0.8, 0.8]))
    rec = oa.add_step([frame(4, 0, X), frame(5, 1, X)], Links([2, 4], [0, 0], [4, 5], [0, 0],
                                                              [1.0, 1.0]))
    assert rec["history_links"] == 1 and rec["sub_links"] == 2
    assert solved[-1] == [False, False, True]          # the history link, refuted
    assert rec["weighed_sets"] == 1 and rec["cut_weigh"] == 0 and rec["cut"] == 0
    assert oa.links.kept.all()
    assert len(set(oa.label[oa.offset[[2, 3, 4, 5]]].tolist())) == 1
