"""The ``no-features`` warning of many images names the first few and counts the rest: a
formation of 1000 robots line abreast (most beside the facade, seeing sky) printed the names
of 731 of them on one line."""

from pipeline.outcome import flag_result

SHOWN = 20  # pipeline.outcome.NAMES_SHOWN


def test_many_images_without_features_are_counted_beyond_the_first_few():
    n = 1000
    counts = [0 if k % 4 else 7 for k in range(n)]  # 750 without features
    names = [f"cam{k:03d}" for k in range(n)]
    report = flag_result({"after": {"conflictive_sets": 0}, "features_per_camera": counts},
                         names=names)
    message = next(w["message"] for w in report["warnings"] if w["code"] == "no-features")
    empty = [names[k] for k in range(n) if counts[k] == 0]
    assert message.startswith(f"no features found in 750 image(s): "
                              f"{', '.join(empty[:SHOWN])} and {750 - SHOWN} more "
                              "(features_per_camera in report.json has each image's count)")
    assert empty[SHOWN] not in message and len(message) < 600


def test_a_few_images_without_features_are_all_named():
    report = flag_result({"after": {"conflictive_sets": 0}, "features_per_camera": [0, 3, 0]},
                         names=["a.png", "b.png", "c.png"])
    message = next(w["message"] for w in report["warnings"] if w["code"] == "no-features")
    assert message == ("no features found in 2 image(s): a.png, c.png (blank, too small or "
                       "too narrow); they take no part")
