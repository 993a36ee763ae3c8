"""Online association (pipeline.consistency.engines.online): conflict-free after every step,
earlier decisions kept outside what new links touch, the history repair, and the batch run."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from online_streams import camera, posed_streams, project, streams

from pipeline.consistency.centralized import is_conflict_free
from pipeline.consistency.engines.online import (
    HISTORY,
    Frame,
    OnlineAssociation,
    batch_resolve,
)
from pipeline.errors import InputError
from pipeline.types import Links


def _run(window, hold, stream, resolution):
    oa = OnlineAssociation(window, resolution=resolution, hold=hold)
    for frames, links in stream:
        before = oa.label.copy()
        rec = oa.add_step(frames, links)
        yield oa, rec, before, links


@pytest.mark.parametrize("resolution", ["paper", "evidence"])
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=streams())
def test_conflict_free_after_every_step(resolution, data):
    window, hold, stream = data
    for oa, rec, _, links in _run(window, hold, stream, resolution):
        assert is_conflict_free(oa.m, oa.kept_links()), rec
        assert rec["links_new"] == len(links)
        assert rec["cut"] == rec["cut_rule"] + rec["cut_weigh"] + rec["cut_history"]


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=streams())
def test_earlier_decisions_are_kept_outside_the_touched_tracks(data):
    _check_earlier_decisions(*data, "paper")


def _check_earlier_decisions(window, hold, stream, resolution):
    prev_kept = np.zeros(0, bool)
    for oa, rec, before, _links in _run(window, hold, stream, resolution):
        L = oa.links
        n_old = len(prev_kept)
        # a cut link is never restored
        assert not (L.kept[:n_old] & ~prev_kept).any()
        # a link cut at this step lies in a track the step's new links touched: one of its
        # ends had a touched label (a border link's retired end keeps its frozen label)
        a = oa.offset[L.ci] + L.fi
        b = oa.offset[L.cj] + L.fj
        new = np.arange(n_old, len(L.ci))
        ends = np.concatenate([a[new], b[new]])
        grown = np.concatenate([before, np.arange(len(before), len(oa.label))])
        touched = np.unique(grown[ends])
        cut_now = np.flatnonzero(L.step_cut == rec["step"])
        assert (np.isin(grown[a[cut_now]], touched)
                | np.isin(grown[b[cut_now]], touched)).all()
        prev_kept = L.kept.copy()


@pytest.mark.parametrize("resolution", ["paper", "evidence"])
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=streams(max_steps=1))
def test_one_step_equals_the_batch_run(resolution, data):
    """All links in one step, nothing retired: the online stage runs the rule on the same
    links (images without links left out, order kept) and decides exactly as the batch."""
    window, hold, stream = data
    (frames, links), = stream
    oa = OnlineAssociation(window, resolution=resolution, hold=hold)
    oa.add_step(frames, links)
    batch = batch_resolve(oa.m, oa.all_links(), resolution=resolution,
                          keypoints=[np.zeros((m, 2)) for m in oa.m])
    assert oa.links.kept.tolist() == (~batch.deleted).tolist()


def test_a_conflict_in_a_retired_frame_is_cut_by_the_history_repair():
    # window 2: the frames of step 0 (images 0, 1) retire at step 2
    oa = OnlineAssociation(window=2, resolution="paper", hold=0)
    oa.add_step([Frame(0, 2), Frame(1, 2)], Links([0, 0], [0, 1], [1, 1], [0, 1]))
    # track A = {0:0, 1:0, 2:0}, track B = {0:1, 1:1, 3:1}
    oa.add_step([Frame(0, 1), Frame(1, 2)], Links([0, 1], [0, 1], [2, 3], [0, 1]))
    # a new frame of robot 0 links to 2:0 (A) and 3:1 (B): the merged set holds images 0 and 1
    # twice, both retired; its window images (2, 3, 4) are all distinct
    rec = oa.add_step([Frame(0, 1), Frame(1, 1)], Links([2, 3], [0, 1], [4, 4], [0, 0],
                                                        [0.9, 0.4]))
    assert rec["conflictive_features"] == 0
    assert rec["cut_history"] == 1
    # the weaker link goes
    assert oa.links.reason.tolist()[-2:] == ["", HISTORY]
    assert oa.is_conflict_free()


def test_a_new_link_must_touch_the_step_and_the_window():
    oa = OnlineAssociation(window=1, resolution="paper")
    oa.add_step([Frame(0, 1), Frame(1, 1)], Links([0], [0], [1], [0]))
    with pytest.raises(InputError, match="window of 1 step$"):
        oa.add_step([Frame(0, 1), Frame(1, 1)], Links([0], [0], [2], [0]))
    with pytest.raises(InputError, match="window"):
        OnlineAssociation(window=0)


def _retired_truth(oa):
    """Centralized: every retired piece's (robot, step) frames, by the piece's name."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    L = oa.links
    a, b = oa.offset[L.ci] + L.fi, oa.offset[L.cj] + L.fj
    retired = ~np.isin(np.arange(oa.n_images), oa.window_images)
    both = L.kept & retired[L.ci] & retired[L.cj]
    n = len(oa.label)
    comp = connected_components(coo_matrix((np.ones(both.sum()), (a[both], b[both])),
                                           shape=(n, n)), directed=False)[1]
    img = np.repeat(np.arange(oa.n_images), oa.m)
    out = {}
    for f in np.flatnonzero(oa.piece >= 0):
        out.setdefault(int(oa.piece[f]), set()).add((int(oa.robot[img[f]]),
                                                     int(oa.step[img[f]])))
        # one name per retired component
        assert (oa.piece[comp == comp[f]] == oa.piece[f]).all() or \
            (oa.piece[comp == comp[f]] < 0).any()
    return out


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=streams(max_steps=10))
def test_retired_runs_cover_their_pieces_frames(data):
    """The entries of a live piece: at most RUNS_PER_ROBOT runs per robot, their steps a
    superset of the piece's frames, exact while a robot has no more runs than that."""
    from pipeline.consistency.engines import online

    window, hold, stream = data
    for oa, _rec, _, _ in _run(window, hold, stream, "paper"):
        truth = _retired_truth(oa)
        for p in np.unique(oa.ret_piece).tolist():
            on = oa.ret_piece == p
            robots, counts = np.unique(oa.ret_robot[on], return_counts=True)
            assert counts.max() <= online.RUNS_PER_ROBOT
            covered = {(int(r), s) for r, lo, hi in zip(oa.ret_robot[on], oa.ret_lo[on],
                                                         oa.ret_hi[on], strict=True)
                       for s in range(int(lo), int(hi) + 1)}
            assert truth[p] <= covered
            if counts.max() < online.RUNS_PER_ROBOT:
                assert truth[p] == covered


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=streams(max_steps=10))
def test_conflict_free_when_runs_are_summarized_to_one(data):
    """RUNS_PER_ROBOT = 1 (each robot's frames of a piece as one span): the history check
    sees more clashes than there are, and the association stays conflict-free."""
    from unittest import mock

    window, hold, stream = data
    with mock.patch("pipeline.consistency.engines.online.RUNS_PER_ROBOT", 1):
        for oa, rec, _, _ in _run(window, hold, stream, "paper"):
            assert is_conflict_free(oa.m, oa.kept_links()), rec
            assert np.unique(np.stack([oa.ret_piece, oa.ret_robot]), axis=1).shape[1] == \
                len(oa.ret_piece)


def test_a_long_track_costs_its_robots_one_run_not_one_entry_per_frame():
    """A track both robots see at every step for 30 steps: its retired frames are one run per
    robot, and a robot's state at the last step is what it was once the window filled."""
    oa = OnlineAssociation(window=2, resolution="paper", hold=0)
    state = []
    for t in range(30):
        g = 2 * t   # images of step t: 2t (robot 0) and 2t + 1 (robot 1)
        ci, fi, cj, fj = [g], [0], [g + 1], [0]
        if t:
            ci += [g - 2, g - 1]
            fi += [0, 0]
            cj += [g, g + 1]
            fj += [0, 0]
        oa.add_step([Frame(0, 2), Frame(1, 2)], Links(ci, fi, cj, fj))
        state.append(oa.robot_state_bytes().tolist())
    assert oa.is_conflict_free() and oa.links.kept.all()
    assert len(np.unique(oa.ret_piece)) == 1
    runs = zip(oa.ret_robot.tolist(), oa.ret_lo.tolist(), oa.ret_hi.tolist(), strict=True)
    assert sorted(runs) == [(0, 0, 27), (1, 0, 27)]
    assert state[-1] == state[3]


@pytest.mark.parametrize("robots_check", [True, False])
def test_two_pieces_sharing_a_retired_frame_are_not_joined(robots_check):
    """Two tracks meet in a retired frame through different features: a new link that joins
    them is cut by the history repair, though every window image of the set is distinct; by
    the robots' check (the default: their pieces named, the entries echoed to a root, the
    repair there, their messages counted) or by the record's own."""
    oa = OnlineAssociation(window=2, resolution="paper", hold=0, robots_check=robots_check)
    # step 0: tracks A = {0:0, 1:0} and B = {0:1, 1:1}
    oa.add_step([Frame(0, 2), Frame(1, 2)], Links([0, 0], [0, 1], [1, 1], [0, 1]))
    # step 1: 2:0 joins A, 3:0 joins B
    oa.add_step([Frame(0, 1), Frame(1, 1)], Links([0, 1], [0, 1], [2, 3], [0, 0]))
    # step 2 (step 0 retired: A and B are two pieces, both in images 0 and 1): 4:0 links to
    # both tracks
    rec = oa.add_step([Frame(0, 1), Frame(1, 1)], Links([2, 3, 4], [0, 0, 0], [4, 4, 5],
                                                        [0, 0, 0], [0.9, 0.5, 0.7]))
    assert oa.piece[:4].tolist() == [0, 1, 0, 1]
    assert rec["conflictive_features"] == 0 and rec["cut_history"] == 1
    assert oa.links.reason.tolist()[-3:] == ["", HISTORY, ""]
    assert oa.is_conflict_free()
    assert (rec.get("history_rounds", 0) > 0) == robots_check and rec["history_bytes"] > 0


@pytest.mark.parametrize("overturn", [True, False])
def test_the_history_repair_may_overturn_a_weak_link_into_a_retired_frame(overturn):
    """Track B reaches the window through a weak link (quality 0.2) from a retired frame; a
    new frame joins A and B. With ``overturn`` the repair adds every open link of the set by
    decreasing quality and the weak link goes (B's piece then has no border link left, its
    entries go); without, it keeps the earlier links and cuts a new one."""
    oa = OnlineAssociation(window=2, resolution="paper", overturn=overturn, hold=0)
    oa.add_step([Frame(0, 2), Frame(1, 2)], Links([0, 0], [0, 1], [1, 1], [0, 1]))
    oa.add_step([Frame(0, 1), Frame(1, 1)], Links([0, 1], [0, 1], [2, 3], [0, 0], [0.9, 0.2]))
    rec = oa.add_step([Frame(0, 1), Frame(1, 1)], Links([2, 3, 4], [0, 0, 0], [4, 4, 5],
                                                        [0, 0, 0], [0.8, 0.9, 0.7]))
    assert rec["cut_history"] == 1 and oa.is_conflict_free()
    reasons = oa.links.reason.tolist()
    if overturn:
        assert reasons == ["", "", "", HISTORY, "", "", ""]
        assert np.unique(oa.ret_piece).tolist() == [oa.piece[0]]
    else:
        assert reasons == ["", "", "", "", HISTORY, "", ""]


@pytest.mark.parametrize("hold", [0, 1])
def test_a_held_link_between_two_old_frames_can_still_be_cut(hold):
    """Window 2: a weak link (quality 0.1) joins tracks B (0:1) and C (1:1) at step 0; the
    clash shows at step 2, when image 4 sees B and C in two features. Without a hold the
    frames of step 0 are retired by then and the weak link is final: the repair cuts a strong
    new link instead. Held one step, the weak link is still open and it is the one the rule
    cuts."""
    oa = OnlineAssociation(window=2, resolution="paper", hold=hold)
    oa.add_step([Frame(0, 2), Frame(1, 2)], Links([0, 0], [0, 1], [1, 1], [0, 1], [0.9, 0.1]))
    oa.add_step([Frame(0, 1), Frame(1, 1)], Links([0, 1], [1, 1], [2, 3], [0, 0], [0.9, 0.9]))
    assert oa.window_images.tolist() == [0, 1, 2, 3]
    rec = oa.add_step([Frame(0, 2), Frame(1, 1)],
                      Links([2, 3], [0, 0], [4, 4], [0, 1], [0.9, 0.9]))
    assert oa.is_conflict_free()
    if hold:
        assert oa.window_images.tolist() == [0, 1, 2, 3, 4, 5]
        assert oa.links.reason.tolist() == ["", "paper", "", "", "", ""]
        assert rec["cut_history"] == 0
    else:
        assert oa.window_images.tolist() == [2, 3, 4, 5]
        assert oa.links.reason.tolist() == ["", "", "", "", "", HISTORY]


def test_a_held_frame_takes_no_new_link():
    oa = OnlineAssociation(window=1, resolution="paper", hold=2)
    oa.add_step([Frame(0, 1), Frame(1, 1)], Links([0], [0], [1], [0]))
    with pytest.raises(InputError, match="window of 1 step$"):
        oa.add_step([Frame(0, 1), Frame(1, 1)], Links([0], [0], [2], [0]))
    with pytest.raises(InputError, match="hold -1"):
        OnlineAssociation(window=1, hold=-1)
    assert OnlineAssociation(window=3).hold == 2


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=streams(max_steps=8))
def test_the_window_holds_window_plus_hold_steps_and_retired_links_stay(data):
    """With any hold: after step t the stage's window is the frames of the last W + H steps,
    the association is conflict-free, and no link between two frames retired before the
    step is cut at it (final), while links of held frames may be."""
    window, hold, stream = data
    prev_retired = np.zeros(0, bool)
    for oa, rec, _, _ in _run(window, hold, stream, "evidence"):
        t = rec["step"]
        assert oa.window_images.tolist() == \
            np.flatnonzero(oa.step > t - window - hold).tolist()
        assert is_conflict_free(oa.m, oa.kept_links()), rec
        L = oa.links
        old = np.zeros(oa.n_images, bool)
        old[:len(prev_retired)] = prev_retired
        cut_now = L.step_cut == t
        assert not (cut_now & old[L.ci] & old[L.cj]).any()
        prev_retired = ~np.isin(np.arange(oa.n_images), oa.window_images)


# ------------------------------------------------------------ weighing the conflict-free sets

def _bundles(oa, a, b, w):
    """The evidence rule's bundles of one set (gid -> kp, neighbours, weights, camera, P)."""
    img = np.searchsorted(oa.offset, np.r_[a, b], side="right") - 1
    ends = np.r_[a, b]
    bundles = {}
    for g in np.unique(ends).tolist():
        im = int(img[ends == g][0])
        mine = np.flatnonzero((a == g) | (b == g))
        other = np.where(a[mine] == g, b[mine], a[mine])
        bundles[g] = (np.asarray(oa.keypoints[im][g - oa.offset[im]], np.float32), other,
                      w[mine], im, oa.projection[im])
    return bundles


@pytest.mark.parametrize("weigh", [True, False])
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=posed_streams(max_steps=1))
def test_one_posed_step_weighs_every_set_by_the_rule(weigh, data):
    """All links in one step, with poses: every set, conflictive or not, ends as the rule's
    solution on it (solve_set, what its robots solve); without weighing, the conflict-free
    sets keep every link (the detection found nothing there)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    from pipeline.consistency.evidence import solve_set
    from pipeline.matching.link_evidence import ratio_llr

    window, hold, stream = data
    (frames, links), = stream
    oa = OnlineAssociation(window, hold=hold, weigh=weigh)
    oa.add_step(frames, links)
    a, b = oa._ends(np.arange(len(links)))
    n = len(oa.label)
    comp = connected_components(coo_matrix((np.ones(len(a)), (a, b)), shape=(n, n)),
                                directed=False)[1][a]
    img = np.searchsorted(oa.offset, np.r_[a, b], side="right") - 1
    local = ratio_llr(1.0 - links.quality)
    expected = np.ones(len(a), bool)
    for c in np.unique(comp).tolist():
        on = np.flatnonzero(comp == c)
        ends = np.r_[a[on], b[on]]
        imgs = np.r_[img[:len(a)][on], img[len(a):][on]]
        clash = len(np.unique(imgs)) < len(np.unique(ends))
        if not weigh and not clash:
            continue
        ra, rb, _, _, cut = solve_set(_bundles(oa, a[on], b[on], local[on]))
        key = {(x, y): k for k, x, y in zip(on.tolist(), np.minimum(a[on], b[on]).tolist(),
                                            np.maximum(a[on], b[on]).tolist(), strict=True)}
        for x, y, c_ in zip(ra.tolist(), rb.tolist(), cut.tolist(), strict=True):
            expected[key[(x, y)]] = not c_
    assert oa.links.kept.tolist() == expected.tolist()
    assert oa.is_conflict_free()


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=posed_streams(max_steps=5))
def test_conflict_free_after_every_posed_step(data):
    window, hold, stream = data
    oa = OnlineAssociation(window, hold=hold)
    for frames, links in stream:
        rec = oa.add_step(frames, links)
        assert is_conflict_free(oa.m, oa.kept_links()), rec
        assert rec["cut"] == rec["cut_rule"] + rec["cut_weigh"] + rec["cut_history"]


@pytest.mark.parametrize("weigh", [True, False])
def test_a_spurious_link_of_a_conflict_free_set_is_cut_by_the_weighing(weigh):
    """Three cameras see a point X; a third frame's feature sees another point Y and is
    linked to X's track (a spurious link, the weakest). The set holds one feature per image:
    the detection finds no conflict. Weighed by the rule's merge, the three-view point of the
    merged track misses Y's keypoint by far and the link is cut; without, it stays."""
    X, Y = np.array([0.5, 0.2, 1.0]), np.array([1.5, -0.4, 0.5])
    P = [camera(x) for x in (0.0, 1.0, 2.0)]
    frames = [Frame(i, 1, project(P[i], X if i < 2 else Y)[None], P[i]) for i in range(3)]
    oa = OnlineAssociation(window=2, weigh=weigh)
    rec = oa.add_step(frames, Links([0, 0, 1], [0, 0, 0], [1, 2, 2], [0, 0, 0],
                                    [0.9, 0.3, 0.2]))
    assert rec["conflictive_features"] == 0 and rec["cut_rule"] == 0
    if weigh:
        assert rec["cut_weigh"] >= 1 and rec["weighed_sets"] == 1
        # the gathering at the root (image 0's feature): two bundles of 128 + 16 * 2 bytes
        # one hop each, then the cut links (16 bytes each) down the two tree edges, and a
        # 12-byte header per message; 2 ecc(root) + 1 rounds
        assert rec["weigh_messages"] == 2 + 2
        assert rec["weigh_bytes"] == 2 * 160 + 2 * 16 * rec["cut_weigh"] + 12 * 4
        assert rec["weigh_rounds"] == 3
        assert oa.links.kept.tolist()[0] and not oa.links.kept[1:].any()
        assert set(oa.links.reason.tolist()[1:]) == {"evidence"}
    else:
        assert oa.links.kept.all() and rec["weighed_sets"] == 0


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=posed_streams(max_steps=5))
def test_the_weighing_cuts_only_in_the_touched_tracks(data):
    """With poses the evidence rule's merge weighs every touched set: a link it cuts still
    lies in a track the step's new links touched, and a cut link is never restored."""
    _check_earlier_decisions(*data, "evidence")


@pytest.mark.parametrize("posed", [False, True])
@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_gathering_the_small_conflictive_sets_decides_as_the_rules_flood(posed, data):
    """The evidence rule's small conflictive sets solved at their roots (``gather``, the
    default) or by the rule's flood to every robot of the set: the same cuts at the same
    steps with the same reasons, the same sets counted (the bytes differ: the flood crosses
    every link of a set, the gathering one path per bundle and back; on a set of two or three
    features the gathering's replies may cost more, ``bench/online.py`` measures a team)."""
    window, hold, stream = data.draw(posed_streams() if posed else streams())
    _assert_alike(window, hold, stream, "gather",
                  ("cut_rule", "cut_weigh", "cut_history", "conflictive_sets", "weighed_sets"))


def _assert_alike(window, hold, stream, option: str, keys) -> OnlineAssociation:
    """Run ``stream`` with ``option`` on and off: the same kept links, reasons and steps of
    the cuts, and the same per-step ``keys``; returns the run with it on."""
    runs = []
    for on in (True, False):
        oa = OnlineAssociation(window, hold=hold, **{option: on})
        runs.append((oa, [oa.add_step(frames, links) for frames, links in stream]))
    (a, ra), (b, rb) = runs
    for name in ("kept", "reason", "step_cut"):
        assert getattr(a.links, name).tolist() == getattr(b.links, name).tolist(), name
    for key in keys:
        assert [r[key] for r in ra] == [r[key] for r in rb], key
    return a


@pytest.mark.parametrize("posed", ["no", "yes", "mixed"])
@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_the_sets_solved_by_the_robots_at_their_roots_are_the_batched_solution(posed, data):
    """``robots_solve``: the stage's robots solve the sets of steps 2 and 2b at their roots
    (pipeline.consistency.roots, every robot on its own inbox in the simulator), as robot
    processes do over a middleware; the default is the batched solution of the same
    protocol (engines.gather.solve_at_roots). Same cuts, steps, reasons and counts of sets,
    whether every frame, none or only some have a pose (robot 0's frames none: a set with
    one of them is solved without the geometric test)."""
    window, hold, stream = data.draw(streams() if posed == "no" else posed_streams())
    if posed == "mixed":
        stream = [([Frame(f.robot, f.m, f.keypoints, None if f.robot == 0 else f.projection)
                    for f in frames], links) for frames, links in stream]
    r = _assert_alike(window, hold, stream, "robots_solve",
                      ("cut", "cut_rule", "cut_weigh", "cut_history", "conflictive_sets",
                       "conflictive_features", "weighed_sets"))
    assert r.is_conflict_free()


@pytest.mark.parametrize("robots_check", [True, False])
def test_a_step_without_new_links_has_every_field_of_a_step_with_links(robots_check):
    # a formation driven off the scene: its frames see nothing, the step makes no link
    oa = OnlineAssociation(window=2, resolution="paper", robots_check=robots_check)
    linked = oa.add_step([Frame(0, 2), Frame(1, 1)], Links([0], [0], [1], [0]))
    empty = oa.add_step([Frame(0, 0), Frame(1, 0)], Links([], [], [], []))
    assert empty["links_new"] == 0
    assert sorted(empty) == sorted(linked)
