"""--merge-radius wider than the images (1e9, or above the shorter side) was accepted: the run
merged each image's keypoints across the whole image and warned only of the images (run-images
blamed 'textureless images'); it is now refused before the features, naming the value and the
range 0 to the shorter side, alike in run-images, run-formation and run-formations."""

import shutil

import pytest

from pipeline.__main__ import main

ALLOWED = "expected pixels from 0 (merges nothing) to"


@pytest.mark.parametrize("mode", [[], ["--sequence"]])
def test_run_images_refuses_a_radius_wider_than_the_photographs(sceaux_small, tmp_path, capsys,
                                                               mode):
    folder = sceaux_small
    if mode:  # one robot's sub-folder each
        folder = tmp_path / "team"
        for robot, names in (("a", ["100_7100.JPG", "100_7102.JPG"]),
                             ("b", ["100_7101.JPG", "100_7103.JPG"])):
            (folder / robot).mkdir(parents=True)
            for k, name in enumerate(names):
                shutil.copy(sceaux_small / name, folder / robot / f"{k}.jpg")
        shutil.copy(sceaux_small / "K.txt", folder / "K.txt")
    out = tmp_path / "run"
    assert main(["run-images", str(folder), *mode, "--max-size", "160", "--merge-radius", "1e9",
                 "--no-rerun", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"error: --merge-radius 1e+09: {ALLOWED} 120, the shorter side of the smallest" in err
    assert "[features]" not in err and not out.exists()


@pytest.mark.parametrize("command", [["run-formation"], ["run-formation", "--steps", "2"],
                                     ["run-formations"]])
@pytest.mark.parametrize("radius", ["1e9", "73"])
def test_rendered_runs_refuse_a_radius_wider_than_size(tmp_path, capsys, command, radius):
    out = tmp_path / "run"
    assert main([*command, "--size", "96x72", "--merge-radius", radius, "--out",
                 str(out)]) == 2
    err = capsys.readouterr().err
    shown = "1e+09" if radius == "1e9" else radius
    assert f"error: --merge-radius {shown}: {ALLOWED} 72, the shorter side of --size 96x72" in err
    assert "[render]" not in err and not out.exists()


def test_run_formation_refuses_inf_before_the_render(tmp_path, capsys):
    """inf was refused only once the formation was rendered."""
    assert main(["run-formation", "--size", "96x72", "--merge-radius", "inf", "--out",
                 str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert "error: --merge-radius inf: expected pixels >= 0" in err and "[render]" not in err


def test_the_shorter_side_itself_is_allowed():
    from pipeline.stages import check_merge_radius

    check_merge_radius(72.0, [(96, 72), (640, 480)], "--size 96x72")
    check_merge_radius(None, [(1, 1)], "x")
