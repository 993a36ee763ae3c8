"""Renderer geometry: pixel convention, depth, determinism."""

import cv2
import numpy as np
import pytest

import data_synth
from data_synth.formations import look_at
from data_synth.renderer import intrinsics, project, render_view
from data_synth.scene import Face, Scene, build_scene

SIZE = (320, 240)


def dot_scene(centre_texel):
    """One 4 m x 3 m wall at y = 5 with a black dot (radius 6 texels) on white."""
    tex = np.full((300, 400, 3), 255, np.uint8)
    cx, cy = centre_texel
    cv2.circle(tex, (int(round(cx * 256)), int(round(cy * 256))), 6 * 256, (0, 0, 0), -1,
               cv2.LINE_AA, 8)
    face = Face("wall", np.array([-2.0, 5.0, 3.0]), np.array([4.0, 0, 0]), np.array([0, 0, -3.0]), tex)
    return Scene(faces=[face], landmarks={}, seed=0), face


@pytest.mark.parametrize("centre, cam", [((200.0, 150.0), (0.0, 0.0, 1.5)),
                                         ((123.25, 77.5), (0.7, 1.0, 1.2))])
def test_texture_landmark_projects_where_it_is_drawn(centre, cam):
    scene, face = dot_scene(centre)
    th, tw = face.texture.shape[:2]
    # texel centre (j, i) sits at a = (j + 0.5) / W, b = (i + 0.5) / H on the face
    X = face.world_point((centre[0] + 0.5) / tw, (centre[1] + 0.5) / th)
    K = intrinsics(SIZE)
    R, t = look_at(cam, X + np.array([0.3, 0, 0.2]))
    img, depth = render_view(scene, K, R, t, SIZE, rng=None)
    (xy,), (z,) = project(K, R, t, X[None])
    dark = 255.0 - img[..., 0].astype(np.float64)
    x0, y0 = int(xy[0]) - 12, int(xy[1]) - 12
    win = dark[y0:y0 + 25, x0:x0 + 25]
    assert win.sum() > 0
    ys, xs = np.mgrid[y0:y0 + 25, x0:x0 + 25]
    centroid = np.array([(xs * win).sum(), (ys * win).sum()]) / win.sum()
    np.testing.assert_allclose(centroid, xy, atol=0.1)
    iy, ix = int(round(xy[1])), int(round(xy[0]))
    assert depth[iy, ix] == pytest.approx(z, rel=2e-3)


def test_depth_is_exact_on_a_plane_and_inf_on_sky():
    scene, face = dot_scene((200.0, 150.0))
    K = intrinsics(SIZE)
    R, t = look_at((0.0, 0.0, 1.5), (0.0, 5.0, 1.5))
    _, depth = render_view(scene, K, R, t, SIZE, rng=None)
    # fronto-parallel wall at distance 5: z = 5 everywhere it covers
    hit = np.isfinite(depth)
    assert hit.mean() > 0.3
    np.testing.assert_allclose(depth[hit], 5.0, rtol=1e-5)
    # sky above the 3 m high wall: no hit
    assert not np.isfinite(depth[0]).any()


def test_scene_corner_and_face_centre_depth():
    f = data_synth.render("a", seed=0, size=SIZE)
    v = f.views[2]
    crate = [fc for fc in f.scene.faces if fc.name == "crate2.side0"][0]  # faces the robots
    X = crate.world_point(0.5, 0.5)
    (xy,), (z,) = project(v.K, v.R, v.t, X[None])
    assert 0 <= xy[0] < SIZE[0] and 0 <= xy[1] < SIZE[1]
    assert v.depth[int(round(xy[1])), int(round(xy[0]))] == pytest.approx(z, rel=0.01)
    xyz, valid = data_synth.points_from_keypoints(v, xy[None])
    assert valid[0]
    np.testing.assert_allclose(xyz[0], X, atol=0.01)
    # the named landmark "top front left corner of crate 2" is a corner of that face
    corner = f.scene.landmarks["crate2.corner1"]
    assert np.dot(corner - crate.origin, crate.normal) == pytest.approx(0.0, abs=1e-9)
    assert min(np.linalg.norm(crate.corners() - corner, axis=1)) == pytest.approx(0.0, abs=1e-9)


def test_render_is_deterministic_by_seed():
    a = data_synth.render("d", seed=3, size=(160, 120), cache=False)
    b = data_synth.render("d", seed=3, size=(160, 120), cache=False)
    c = data_synth.render("d", seed=4, size=(160, 120), cache=False)
    for va, vb in zip(a.views, b.views, strict=True):
        assert np.array_equal(va.image, vb.image)
        assert np.array_equal(va.depth, vb.depth)
        assert np.array_equal(va.R, vb.R) and np.array_equal(va.t, vb.t)
    assert not np.array_equal(a.views[0].image, c.views[0].image)
    # the scene textures themselves, rebuilt without the cache
    s1, s2 = build_scene.__wrapped__(3), build_scene.__wrapped__(3)
    assert all(np.array_equal(x.texture, y.texture) for x, y in zip(s1.faces, s2.faces, strict=True))


def test_formations_share_images_and_views_are_complete():
    fa = data_synth.render("a", seed=0, size=(160, 120))
    fd = data_synth.render("d", seed=0, size=(160, 120))
    assert np.array_equal(fa.views[4].image, fd.views[4].image)
    for v in fd.views:
        assert v.image.shape == (120, 160, 3) and v.image.dtype == np.uint8
        assert v.depth.shape == (120, 160) and v.depth.dtype == np.float32
        assert v.K.shape == (3, 3) and v.intrinsics_known
        np.testing.assert_allclose(v.R @ v.R.T, np.eye(3), atol=1e-12)
        # texture everywhere: the scene fills most of the view
        assert np.isfinite(v.depth).mean() > 0.9
