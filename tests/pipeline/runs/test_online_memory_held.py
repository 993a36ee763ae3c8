"""A robot's memory in an online run (pipeline.runs.online): the frames of its matching
window cost their keypoints and descriptors, the held frames (window + hold) their keypoints
only, plus the stage's state."""


def test_the_last_steps_memory_counts_held_frames_without_descriptors():
    from pipeline.runs.online import OnlineConfig, run_online_steps

    config = OnlineConfig(formation="ring", robots=3, graph="ring", size=(192, 144),
                          max_features=150, steps=3, window=2, fusion=False, rerun=False)
    run = run_online_steps(config, batch_steps=set())
    oa, t = run.online, 2
    w = oa.window_images
    held = w[oa.step[w] <= t - config.window]
    assert oa.hold == 1 and len(held) == 3       # step 0's frames, one per robot
    want = oa.robot_state_bytes().copy()
    for g in w.tolist():
        f = run.features[g]
        want[oa.robot[g]] += f.keypoints.nbytes + (0 if g in held else f.descriptors.nbytes)
    assert all(run.features[g].descriptors.nbytes > 0 for g in held)
    assert run.steps[-1]["robot_memory_bytes_max"] == int(want.max())
