"""The rendered ring round a tower of repeated modules: a photo folder with its exact truth."""

import cv2
import numpy as np
import pytest

from data_synth.symmetric import TOWER_HEIGHT_M, build_tower_scene, ring_poses, write_ring_folder
from pipeline.evaluation.scene_truth import read_truth


def test_equal_letters_are_exact_copies_and_the_others_differ():
    scene = build_tower_scene(0, "AABB")
    tex = {}
    for f in scene.faces:
        side = f.name.split("[")[0]
        if side.startswith("tower"):
            tex.setdefault(side, []).append(f.texture)
    # shading scales a side by its normal: copies are equal up to that factor
    flat = {k: np.concatenate([a.reshape(-1) for a in v]).astype(np.float64)
            for k, v in tex.items()}
    assert len(flat) == 4
    assert np.corrcoef(flat["tower0"], flat["tower1"])[0, 1] > 0.99
    assert np.corrcoef(flat["tower2"], flat["tower3"])[0, 1] > 0.99
    assert np.corrcoef(flat["tower1"], flat["tower2"])[0, 1] < 0.9
    with pytest.raises(ValueError, match="four letters"):
        build_tower_scene(0, "AB")


def test_ring_cameras_look_at_the_tower():
    for R, t in ring_poses(6):
        centre = -R.T @ t
        assert np.linalg.norm(centre[:2]) == pytest.approx(10.0)
        forward = R[2]
        assert np.dot(forward, np.array([0, 0, 2.5]) - centre) > 0.99 * np.linalg.norm(
            np.array([0, 0, 2.5]) - centre)


def test_written_folder_holds_images_and_a_truth_that_agrees_with_them(tmp_path):
    out = write_ring_folder(tmp_path / "ring", n=3, size=(160, 120))
    names = sorted(p.name for p in out.glob("*.png"))
    assert names == ["cam00.png", "cam01.png", "cam02.png"]
    truth = read_truth(out)
    assert truth.names == names and truth.depth.shape == (3, 120, 160)
    img = cv2.imread(str(out / names[0]))
    assert img.shape == (120, 160, 3)
    # the tower's top corner projects where the depth says a surface at its distance is
    X = np.array([0.0, 0.0, TOWER_HEIGHT_M / 2])
    for k in range(3):
        x = truth.K[k] @ (truth.R[k] @ X + truth.t[k])
        u, v = int(round(x[0] / x[2])), int(round(x[1] / x[2]))
        assert truth.depth[k][v, u] < x[2]  # the tower's side is in front of its centre
        assert truth.depth[k][v, u] > x[2] - 2.0 * np.sqrt(2)
