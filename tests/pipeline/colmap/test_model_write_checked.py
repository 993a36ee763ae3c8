"""A COLMAP model folder that cannot be written whole is an error naming it: COLMAP's writer
ignores a failed write (a full disk, a file-size limit) and left truncated .bin files, which a
run folder then carried (run-images on a full disk: a traceback, IndexError unordered_map::at,
from reading them back)."""

import errno
import resource
import shutil
from contextlib import contextmanager

import numpy as np
import pycolmap
import pytest

from pipeline.colmap import write_model
from pipeline.colmap.base import write_reconstruction


def _reconstruction(points=400):
    rec = pycolmap.Reconstruction()
    cam = pycolmap.Camera(model="PINHOLE", width=640, height=480, params=[500, 500, 320, 240],
                          camera_id=1)
    rec.add_camera_with_trivial_rig(cam)
    rng = np.random.default_rng(0)
    for image_id in (1, 2):
        kp = rng.uniform(0, 480, (points, 2))
        image = pycolmap.Image(name=f"{image_id}.jpg", keypoints=kp, camera_id=1,
                               image_id=image_id)
        rec.add_image_with_trivial_frame(image, pycolmap.Rigid3d())
    for k in range(points):
        track = pycolmap.Track()
        track.add_element(1, k)
        track.add_element(2, k)
        rec.add_point3D(rng.uniform(-1, 1, 3) + [0, 0, 5], track, np.zeros(3, np.uint8))
    return rec


@contextmanager
def _file_size_limit(nbytes):
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    resource.setrlimit(resource.RLIMIT_FSIZE, (nbytes, hard))  # Python ignores SIGXFSZ
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))


def test_a_whole_model_is_written_and_reads_back(tmp_path):
    rec = _reconstruction()
    write_model(tmp_path / "sparse", rec)
    back = pycolmap.Reconstruction(str(tmp_path / "sparse"))
    assert (back.num_images(), back.num_points3D()) == (2, 400)


def test_a_truncated_model_is_an_error_naming_the_folder(tmp_path):
    rec = _reconstruction()
    with _file_size_limit(4096), pytest.raises(OSError) as info:
        write_model(tmp_path / "sparse", rec)
    assert info.value.filename == str(tmp_path / "sparse")
    assert info.value.errno == errno.EIO and "not written whole" in info.value.strerror


def test_a_full_disk_is_named_as_such(tmp_path, monkeypatch):
    rec = _reconstruction()
    usage = shutil.disk_usage(tmp_path)
    monkeypatch.setattr(shutil, "disk_usage", lambda path: usage._replace(free=0))
    (tmp_path / "sparse").mkdir()
    with _file_size_limit(4096), pytest.raises(OSError) as info:
        write_reconstruction(rec, tmp_path / "sparse")
    assert info.value.errno == errno.ENOSPC and info.value.filename == str(tmp_path / "sparse")
