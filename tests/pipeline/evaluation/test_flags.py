"""Flags of a photo run: a weak reconstruction and cleaning that hurt are never silent."""

import numpy as np

from pipeline.evaluation.flags import flags_markdown, reconstruction_flags


def _summary(reg, names, points, track=4.0, err=0.5):
    return {"registered_images": reg, "registered_names": names, "points": points,
            "mean_track_length": track, "mean_reprojection_error": err}


NAMES = [f"{k}.jpg" for k in range(6)]
RING = np.array([[k, (k + 1) % 6] for k in range(6)])


def test_a_good_run_has_no_flags():
    s = _summary(6, NAMES, 1000)
    assert reconstruction_flags(6, s, s, RING, [100] * 6, [5000] * 6) == []
    assert flags_markdown([]) == ""


def test_few_registered_names_the_likely_causes():
    before = _summary(2, NAMES[:2], 40)
    split = np.array([[0, 1], [2, 3], [4, 5]])
    flags = reconstruction_flags(6, before, before, split, [50, 0, 0], [600] * 6,
                                 intrinsics_guessed=6)
    assert [f["flag"] for f in flags] == ["few-registered"]
    cause = flags[0]["likely_cause"]
    assert "3 groups" in cause and "2 of 3 image pairs got no association" in cause
    assert "few features" in cause and "guessed" in cause
    assert "registered only 2 of 6" in flags_markdown(flags)


def test_no_feature_in_any_image_is_the_cause_named():
    """Tiny or plain images where the detector found nothing: the cause is the missing
    features, not matches the ratio and epipolar tests rejected (there were none)."""
    none = dict(_summary(0, [], 0), models=0)
    flags = reconstruction_flags(3, none, none, np.array([[0, 1], [0, 2], [1, 2]]), [0] * 3,
                                 [0] * 3, intrinsics_guessed=3)
    cause = flags[0]["likely_cause"]
    assert cause.startswith("no image has any feature (the detector found none in the 3 "
                            "images)")
    assert "--features" in cause and "ratio and epipolar" not in cause


def test_no_model_at_all_names_colmaps_first_pair():
    """Two photos matched well (574 links) but COLMAP started no model: the first cause named
    is its first pair's thresholds, not only the guessed focal length."""
    none = dict(_summary(0, [], 0), models=0)
    flags = reconstruction_flags(2, none, none, np.array([[0, 1]]), [574], [5000] * 2,
                                 intrinsics_guessed=2)
    cause = flags[0]["likely_cause"]
    assert cause.startswith("COLMAP found no image pair to start its model from, though "
                            "matching linked up to 574 features of a pair")
    assert "guessed" in cause
    # a model that started but stayed small: no such cause
    small = dict(_summary(1, NAMES[:1], 10), models=1)
    flags = reconstruction_flags(6, small, small, RING, [100] * 6, [5000] * 6)
    assert "no image pair to start" not in flags[0]["likely_cause"]


def test_a_reconstruction_at_the_relaxed_threshold_is_flagged():
    """The model before cleaning was mapped again at the relaxed registration threshold: the
    run says what COLMAP's threshold registered and at how many points the rest were."""
    before = dict(_summary(6, NAMES, 1000), min_pose_inliers=15, registered_at_colmap_default=2)
    flags = reconstruction_flags(6, before, before, RING, [100] * 6, [5000] * 6)
    assert [f["flag"] for f in flags] == ["relaxed-registration"]
    assert "registered 2 of 6" in flags[0]["message"] and "at 15 points 6" in flags[0]["message"]
    # at COLMAP's own threshold: no flag
    plain = dict(_summary(6, NAMES, 1000), min_pose_inliers=30)
    assert reconstruction_flags(6, plain, plain, RING, [100] * 6, [5000] * 6) == []


def test_images_lost_after_cleaning_name_the_images_and_the_cuts():
    before, after = _summary(6, NAMES, 1000), _summary(5, NAMES[:5], 990)
    flags = reconstruction_flags(6, before, after, RING, [100] * 6, [5000] * 6,
                                 cut_by_reason={"fusion-outlier": 30, "resolution": 2},
                                 lost_image_cuts={"5.jpg": {"fusion-outlier": 25}})
    assert [f["flag"] for f in flags] == ["images-lost"]
    assert "5.jpg" in flags[0]["message"] and "25 links cut by fusion-outlier" in \
        flags[0]["likely_cause"]


def test_cleaning_that_costs_points_or_accuracy_is_flagged_not_small_noise():
    before = _summary(6, NAMES, 1000, track=4.0, err=0.50)
    assert reconstruction_flags(6, before, _summary(6, NAMES, 980, 3.95, 0.51), RING,
                                [100] * 6, [5000] * 6) == []
    flags = reconstruction_flags(6, before, _summary(6, NAMES, 700, 3.0, 0.7), RING,
                                 [100] * 6, [5000] * 6, cut_by_reason={"resolution": 9})
    assert [f["flag"] for f in flags] == ["cleaning-worse"]
    msg = flags[0]["message"]
    assert "points 1000 -> 700" in msg and "track length" in msg and "reprojection" in msg
    assert "9 by resolution" in flags[0]["likely_cause"]
    # fewer points but each more accurate, tracks as long: what cleaning is for, not flagged
    assert reconstruction_flags(6, _summary(6, NAMES, 200, 3.0, 0.50),
                                _summary(6, NAMES, 187, 3.0, 0.45), RING, [100] * 6,
                                [5000] * 6) == []
    flags = reconstruction_flags(6, _summary(6, NAMES, 200, 3.0, 0.50),
                                 _summary(6, NAMES, 187, 3.0, 0.50), RING, [100] * 6, [5000] * 6)
    assert [f["flag"] for f in flags] == ["cleaning-worse"]


def test_cameras_colmap_deems_bogus_are_flagged_by_name():
    """sparse/ with a camera COLMAP's mapper would reject (e.g. k = 24.7 on 80x60 images) is
    not written silently."""
    before = _summary(6, NAMES, 1000)
    after = {**before, "bogus_camera_images": ["1.jpg", "4.jpg"]}
    flags = reconstruction_flags(6, before, after, RING, [100] * 6, [5000] * 6)
    assert [f["flag"] for f in flags] == ["bogus-cameras"]
    assert "2 registered image(s)" in flags[0]["message"]
    assert "1.jpg, 4.jpg" in flags[0]["message"] and "K.txt" in flags[0]["likely_cause"]


def test_bogus_camera_images_reads_colmaps_own_test():
    """The registered images whose camera fails Camera.has_bogus_params with the mapper's
    thresholds (here a radial term of 24.7), by name; none without a reconstruction."""
    import pycolmap

    from pipeline.colmap.mapping import bogus_camera_images, poses_usable

    assert bogus_camera_images(None) == []
    rec = pycolmap.Reconstruction()
    for cid, k in ((1, 0.1), (2, 24.7), (3, 0.0)):
        cam = pycolmap.Camera(model="SIMPLE_RADIAL", width=80, height=60,
                              params=[70, 40, 30, k], camera_id=cid)
        rec.add_camera_with_trivial_rig(cam)
        rec.add_image_with_trivial_frame(pycolmap.Image(name=f"{cid}.png", camera_id=cid,
                                                        image_id=cid), pycolmap.Rigid3d())
    assert rec.num_reg_images() == 3
    assert bogus_camera_images(rec) == ["2.png"]
    assert not poses_usable(rec)


def test_images_left_unregistered_are_named_even_above_half():
    """Four of six registered: not "few", but the two left out were said nowhere (the report
    showed 4 registered images, nothing more)."""
    before = _summary(4, NAMES[:4], 800)
    flags = reconstruction_flags(6, before, before, RING, [100] * 6, [5000] * 6,
                                 image_names=NAMES)
    assert [f["flag"] for f in flags] == ["unregistered"]
    assert flags[0]["message"] == "the reconstruction left 2 of 6 images unregistered: 4.jpg, 5.jpg"
    assert "run them as a folder of their own" in flags[0]["likely_cause"]


def test_the_images_of_colmaps_other_models_are_named():
    names = [f"{k:02d}.jpg" for k in range(14)]
    before = dict(_summary(8, names[:8], 900),
                  other_models=[names[8:12], names[12:14]])
    flags = reconstruction_flags(14, before, before, np.array([[k, k + 1] for k in range(13)]),
                                 [100] * 13, [5000] * 14, image_names=names)
    assert [f["flag"] for f in flags] == ["unregistered"]
    assert flags[0]["message"] == (
        "the reconstruction left 6 of 14 images unregistered: 08.jpg, 09.jpg, 10.jpg, 11.jpg, "
        "12.jpg and 1 more; COLMAP made 3 models and sparse/ holds the largest only: the other "
        "models registered 6 image(s) (08.jpg, 09.jpg, 10.jpg, 11.jpg, 12.jpg and 1 more)")


def test_each_figure_is_flagged_alone_just_past_five_percent():
    before = _summary(6, NAMES, 1000, track=4.0, err=0.50)
    for after, what in ((_summary(6, NAMES, 1000, 3.7, 0.50), "mean track length 4.00 -> 3.70"),
                        (_summary(6, NAMES, 1000, 4.0, 0.54), "mean reprojection error 0.500 -> 0.540 px"),
                        (_summary(6, NAMES, 940, 4.0, 0.50), "points 1000 -> 940")):
        flags = reconstruction_flags(6, before, after, RING, [100] * 6, [5000] * 6)
        assert [f["flag"] for f in flags] == ["cleaning-worse"], what
        assert flags[0]["message"] == "cleaning made the reconstruction worse: " + what
    # within 5 % each: not flagged
    assert reconstruction_flags(6, before, _summary(6, NAMES, 960, 3.85, 0.52), RING,
                                [100] * 6, [5000] * 6) == []
