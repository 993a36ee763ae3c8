"""An online step's matching in robot processes (pipeline.team.online_match): every pair of
the step matched once, by one robot, as the simulator matches it; each robot's folder holds
its window's frames only."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.matching.pairs import step_pairs
from pipeline.team.online_match import own_pairs


@settings(max_examples=200, deadline=None)
@given(n=st.integers(1, 6), t=st.integers(0, 6), window=st.integers(1, 4),
       edges=st.sets(st.tuples(st.integers(0, 5), st.integers(0, 5)), max_size=12))
def test_every_pair_of_the_step_is_one_robots(n, t, window, edges):
    edges = np.array(sorted({(min(a, b), max(a, b)) for a, b in edges
                             if a != b and a < n and b < n}), np.int64).reshape(-1, 2)
    robot_of = np.arange((t + 1) * n) % n
    step_of = np.arange((t + 1) * n) // n
    want = [tuple(p) for p in step_pairs(robot_of, step_of, t, window, edges).tolist()]
    mine = []
    for i in range(n):
        nbrs = set(edges[edges[:, 0] == i, 1].tolist()) | set(edges[edges[:, 1] == i, 0].tolist())
        mine += own_pairs(i, n, t, window, nbrs)
    assert sorted(mine) == want  # the same pairs, none matched twice


@pytest.fixture(scope="module")
def sequence():
    from data_synth.motion import render_motion

    return render_motion("d", 0, 3, (160, 120), 3, window=2)


def test_robots_match_as_the_simulator_and_keep_their_window(sequence, tmp_path):
    """Three steps of a 3-robot formation, window 2: the links of each step that the robot
    processes give equal the simulator's, and after each step robot i's folder holds exactly
    its frames of the last two steps (the simulator's store the same frames) and the frames
    its neighbours sent it in that window, each sent once."""
    from pipeline.matching.features import MERGE_RADIUS_PX
    from pipeline.runs.transports import sim, zenoh

    views, n, window = sequence.flat.views, sequence.n_robots, 2
    kw = dict(features="sift", max_features=300, merge_radius=MERGE_RADIUS_PX,
              feature_options={}, match_options={})
    needed, messages = set(), 0
    with sim.online_robots() as memory:
        for t in range(3):
            edges = sequence.step_edges[t]
            f_z, l_z, s_z = zenoh.online_match(views, t, n, window, edges, tmp_path, **kw)
            f_s, l_s, s_s = sim.online_match(views, t, n, window, edges, memory, **kw)
            assert len(l_s) > 0
            for a, b in ((l_z.cam_i, l_s.cam_i), (l_z.feat_i, l_s.feat_i), (l_z.cam_j, l_s.cam_j),
                         (l_z.feat_j, l_s.feat_j), (l_z.quality, l_s.quality)):
                np.testing.assert_array_equal(a, b)
            for i in range(n):
                np.testing.assert_array_equal(f_z[i].keypoints, f_s[i].keypoints)
                held = sorted(int(p.stem.split("-")[1])
                              for p in (tmp_path / f"robot-{i}").glob("*.npz"))
                window_frames = [s * n + i for s in range(max(0, t - window + 1), t + 1)]
                assert [g for g in held if g % n == i] == window_frames
                assert all(g // n > t - window for g in held)  # and its neighbours' in it
                assert sorted(g for g in memory if g % n == i) == window_frames
                nbrs = {int(b) for a, b in edges if a == i} | {int(a) for a, b in edges if b == i}
                for j in nbrs:  # j matches with i's earlier window frames, and with its
                    # new one when i > j
                    needed |= {(g, i, j) for g in window_frames[:-1]}
                    needed |= {(t * n + i, i, j)} if i > j else set()
            messages += s_z["messages"]
            assert s_z["bytes"] > 0 and s_z["descriptor_bytes"] == s_s["descriptor_bytes"]
    assert messages == len(needed)  # each frame crossed each link once


class _CutOff:
    """A transport on which neighbour 1 was written off before it sent anything."""

    neighbours = frozenset({1})
    silent = frozenset({1})

    def send(self, dst, kind, payload):
        pass

    def end_round(self, state=None):
        return [], {}

    def counters(self):
        return {"messages": 0, "bytes": 0}


def test_a_neighbour_lost_before_its_frame_came_is_named(sequence, tmp_path):
    """Robot 0 of a 3-robot team matches the two new frames of step 0 (its own and robot 1's);
    robot 1 lost before sending its frame: robot 0 publishes the frame as ``missing`` and no
    pair (it read a file of its own folder that was never written, and said only that the
    file did not exist), and the launching process starts the step's matching again."""
    from pipeline.matching.features import MERGE_RADIUS_PX
    from pipeline.runs.transports.zenoh import team_options
    from pipeline.team.launcher import make_team
    from pipeline.team.online_match import online_match_main, write_frame

    views, n = sequence.flat.views, sequence.n_robots
    frames = []
    for i in range(n):
        frames.append(str(tmp_path / f"camera-{i}.npz"))
        write_frame(frames[-1], views[i])
    data = {"kind": "online-match", "step": 0, "window": 2, "frames": frames,
            "store": [str(tmp_path / f"robot-{i}") for i in range(n)]}
    team = make_team("online-match-0", [[0, 1], [1, 2]], data,
                     team_options("sift", 300, None, merge_radius=MERGE_RADIUS_PX), n=n)
    header, arrays = online_match_main(team, 0, _CutOff())
    assert header["missing"] == [1] and header["pairs"] == []
    assert len(arrays["keypoints"]) > 0


class _Recorder(_CutOff):
    """A transport that records what robot 0 sends its neighbour 1 and hears nothing."""

    def __init__(self):
        self.sent = []

    def send(self, dst, kind, payload):
        self.sent.append(int(payload["id"][0]))


def test_a_matching_started_again_sends_every_window_frame_again(sequence, tmp_path):
    """``data.resend``: a robot whose step's matching is started again sends its neighbours
    the window frames its ``sent.json`` says they hold (the lost team may have sent them
    to a robot that died before keeping them)."""
    from pipeline.matching.features import MERGE_RADIUS_PX
    from pipeline.runs.transports.zenoh import team_options
    from pipeline.team.launcher import make_team
    from pipeline.team.online_match import online_match_main, write_frame

    views, n = sequence.flat.views, sequence.n_robots
    store = [str(tmp_path / f"robot-{i}") for i in range(n)]
    opts = team_options("sift", 300, None, merge_radius=MERGE_RADIUS_PX)
    sent = {}
    for t, resend in ((0, False), (1, False), (1, True)):
        frames = []
        for i in range(n):
            frames.append(str(tmp_path / f"camera-{t}-{i}.npz"))
            write_frame(frames[-1], views[t * n + i])
        data = {"kind": "online-match", "step": t, "window": 2, "frames": frames,
                "store": store, **({"resend": True} if resend else {})}
        team = make_team(f"online-match-{t}", [[0, 1], [1, 2]], data, opts, n=n)
        rec = _Recorder()
        online_match_main(team, 0, rec)
        sent[(t, resend)] = rec.sent
    # step 0: robot 0's new frame goes to robot 1 only if 0 > 1: nothing; step 1: its frame
    # of step 0 (not sent before); started again, the same frame again, not held as sent
    assert sent[(0, False)] == [] and sent[(1, False)] == [0] and sent[(1, True)] == [0]


@settings(max_examples=200, deadline=None)
@given(n=st.integers(1, 5), t=st.integers(0, 5), window=st.integers(1, 4),
       edges=st.sets(st.tuples(st.integers(0, 4), st.integers(0, 4)), max_size=10),
       data=st.data())
def test_void_frames_leave_exactly_their_pairs_out(n, t, window, edges, data):
    """``data.void``: the robots' pairs are the step's pairs without those touching a void
    frame, each still matched by one robot."""
    edges = np.array(sorted({(min(a, b), max(a, b)) for a, b in edges
                             if a != b and a < n and b < n}), np.int64).reshape(-1, 2)
    robot_of = np.arange((t + 1) * n) % n
    step_of = np.arange((t + 1) * n) // n
    earlier = list(range(max(0, t - window + 1) * n, t * n))
    void = set(data.draw(st.lists(st.sampled_from(earlier), unique=True))) if earlier else set()
    want = [tuple(p) for p in step_pairs(robot_of, step_of, t, window, edges).tolist()
            if p[0] not in void and p[1] not in void]
    mine = []
    for i in range(n):
        nbrs = set(edges[edges[:, 0] == i, 1].tolist()) | set(edges[edges[:, 1] == i, 0].tolist())
        mine += own_pairs(i, n, t, window, nbrs, sorted(void))
    assert sorted(mine) == want


def _run_robot0(sequence, tmp_path, t: int, transport, **extra):
    from pipeline.matching.features import MERGE_RADIUS_PX
    from pipeline.runs.transports.zenoh import team_options
    from pipeline.team.launcher import make_team
    from pipeline.team.online_match import online_match_main, write_frame

    views, n = sequence.flat.views, sequence.n_robots
    frames = []
    for i in range(n):
        frames.append(str(tmp_path / f"camera-{t}-{i}.npz"))
        write_frame(frames[-1], views[t * n + i])
    data = {"kind": "online-match", "step": t, "window": 2, "frames": frames,
            "store": [str(tmp_path / f"robot-{i}") for i in range(n)], **extra}
    team = make_team(f"online-match-{t}", [[0, 1], [1, 2]], data,
                     team_options("sift", 300, None, merge_radius=MERGE_RADIUS_PX), n=n)
    return online_match_main(team, 0, transport)


def test_a_robot_matches_the_pairs_it_has_and_names_the_frames_that_never_came(
        sequence, tmp_path):
    """Step 1: robot 0's neighbour 1 was written off before sending its frames: robot 0
    names them ``missing`` and still matches its new frame against its own of step 0 (the
    launching process keeps that pair if the step goes on without robot 1)."""
    _run_robot0(sequence, tmp_path, 0, _Recorder())
    header, arrays = _run_robot0(sequence, tmp_path, 1, _CutOff())
    n = sequence.n_robots
    assert header["missing"] == [1, n + 1]
    assert [(p["a"], p["b"]) for p in header["pairs"]] == [(0, n)]
    assert f"pairs_0_{n}" in arrays


def test_a_void_frame_is_dropped_never_sent_and_never_matched(sequence, tmp_path):
    """``data.void`` names robot 0's frame of step 0 (say it was killed after storing it,
    before publishing): at step 1 robot 0 deletes it from its folder, does not send it to
    robot 1, and matches no pair with it."""
    _run_robot0(sequence, tmp_path, 0, _Recorder())
    assert (tmp_path / "robot-0" / "frame-0.npz").exists()
    rec = _Recorder()
    header, _ = _run_robot0(sequence, tmp_path, 1, rec, void=[0])
    n = sequence.n_robots
    assert rec.sent == []
    assert not (tmp_path / "robot-0" / "frame-0.npz").exists()
    assert all(0 not in (p["a"], p["b"]) for p in header["pairs"])
    assert header["missing"] == [1, n + 1]
