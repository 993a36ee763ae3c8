"""Labelled-landmark folders: pairing by name or by natural order, txt / mat keypoints,
given or SIFT descriptors, frame selection, and clear errors."""

from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from scipy.io import savemat

from pipeline.errors import InputError
from pipeline.inputs.landmarks import load_landmark_folder, natural_key, select_frames

HOTEL = Path(__file__).resolve().parents[2] / "data" / "cmu_hotel_small"


def _image(path: Path, size=(64, 48)) -> None:
    rng = np.random.default_rng(len(path.name))
    Image.fromarray(rng.integers(0, 255, size[::-1], dtype=np.uint8)).save(path)


def test_natural_order():
    names = ["hotel.seq10.png", "hotel.seq2.png", "hotel.seq0.png"]
    assert sorted(names, key=natural_key) == ["hotel.seq0.png", "hotel.seq2.png", "hotel.seq10.png"]


def test_select_frames_stride_from_first():
    assert select_frames(101, 20).tolist() == list(range(0, 100, 5))
    assert select_frames(6, None).tolist() == list(range(6))
    with pytest.raises(InputError, match="--frames 1"):
        select_frames(6, 1)
    with pytest.raises(InputError, match="--frames 7"):
        select_frames(6, 7)


def test_hotel_subset_pairs_files_by_natural_order():
    frames = load_landmark_folder(HOTEL)
    assert [f.name for f in frames] == [f"hotel.seq{k}.png" for k in (0, 20, 40, 60, 80, 100)]
    assert [f.keypoint_file for f in frames] == [f"hotel{k}.txt" for k in (1, 21, 41, 61, 81, 101)]
    assert [f.descriptor_file for f in frames] == [f"hotel{k:03d}.scf" for k in (1, 21, 41, 61, 81, 101)]
    assert all(f.keypoints.shape == (30, 2) and f.descriptors.shape == (30, 60) for f in frames)
    assert frames[0].descriptor_kind == "histogram"
    np.testing.assert_allclose(frames[0].keypoints[0], [164, 82])


def test_pairing_by_name_with_mat_and_txt(tmp_path):
    pts = np.array([[10.0, 12.0], [30.0, 20.0], [50.0, 40.0]])
    for k in range(3):
        _image(tmp_path / f"view{k}.png")
    np.savetxt(tmp_path / "view0.txt", pts)
    savemat(tmp_path / "view1.mat", {"pts_coord": pts.T})
    np.savetxt(tmp_path / "view2.txt", pts + 1, delimiter=",")
    (tmp_path / "SOURCE.txt").write_text("not a keypoint table\n")
    frames = load_landmark_folder(tmp_path, descriptors="sift")
    assert [f.keypoint_file for f in frames] == ["view0.txt", "view1.mat", "view2.txt"]
    np.testing.assert_allclose(frames[1].keypoints, pts)
    assert frames[0].descriptors.shape == (3, 128) and frames[0].descriptor_kind == "vector"


def test_different_landmark_counts_is_an_input_error(tmp_path):
    for k in range(2):
        _image(tmp_path / f"v{k}.png")
    np.savetxt(tmp_path / "v0.txt", np.ones((3, 2)))
    np.savetxt(tmp_path / "v1.txt", np.ones((4, 2)))
    with pytest.raises(InputError, match="different numbers of landmarks"):
        load_landmark_folder(tmp_path, descriptors="sift")


def test_unpaired_files_and_missing_descriptors(tmp_path):
    for k in range(3):
        _image(tmp_path / f"v{k}.png")
    np.savetxt(tmp_path / "a.txt", np.ones((3, 2)))
    with pytest.raises(InputError, match="3 images but 1 keypoint files"):
        load_landmark_folder(tmp_path)
    for k in range(3):
        np.savetxt(tmp_path / f"v{k}.txt", np.ones((3, 2)))
    (tmp_path / "a.txt").unlink()
    with pytest.raises(InputError, match="NAME.scf"):
        load_landmark_folder(tmp_path, descriptors="given")
    for k in range(3):
        np.savetxt(tmp_path / f"v{k}.scf", np.ones((2, 5)))
    with pytest.raises(InputError, match="2 descriptor rows for 3 landmarks"):
        load_landmark_folder(tmp_path, descriptors="given")


def test_missing_folder_and_bad_descriptor_source(tmp_path):
    with pytest.raises(InputError, match="no such folder"):
        load_landmark_folder(tmp_path / "nope")
    with pytest.raises(InputError, match="--descriptors 'orb'"):
        load_landmark_folder(HOTEL, descriptors="orb")


def test_auto_descriptors_read_given_files_and_compute_sift_without_them(tmp_path):
    """The default (``auto``): the ``.scf`` files where the folder has them, SIFT at the
    keypoints where it ships only images and keypoints (e.g. ``.mat`` files alone)."""
    assert [f.descriptor_file for f in load_landmark_folder(HOTEL)][0] == "hotel001.scf"
    pts = np.array([[10.0, 12.0], [30.0, 20.0], [50.0, 40.0]])
    for k in range(3):
        _image(tmp_path / f"view{k}.png")
        savemat(tmp_path / f"view{k}.mat", {"pts_coord": pts.T + k})
    frames = load_landmark_folder(tmp_path)
    assert [f.descriptor_file for f in frames] == ["sift"] * 3
    assert frames[0].descriptors.shape == (3, 128)
    for k in range(3):  # descriptor files that do not fit are still an error under auto
        np.savetxt(tmp_path / f"view{k}.scf", np.ones((2, 5)))
    with pytest.raises(InputError, match="2 descriptor rows for 3 landmarks"):
        load_landmark_folder(tmp_path)


def test_a_landmark_an_image_does_not_see_is_a_nan_row(tmp_path):
    """``nan nan`` rows: the image has a feature per landmark it sees, in label order, and
    ``landmarks`` names each feature's label row; descriptor rows of unseen landmarks are not
    read (they may be nan); a half-nan row, or an image that sees nothing, is an error."""
    pts = np.array([[10.0, 12.0], [30.0, 20.0], [50.0, 40.0], [20.0, 30.0]])
    for k in range(3):
        _image(tmp_path / f"view{k}.png")
        rows = pts.copy()
        rows[k] = np.nan  # image k does not see landmark k
        np.savetxt(tmp_path / f"view{k}.txt", rows)
        d = np.arange(20.0).reshape(4, 5) + k
        d[k] = np.nan
        np.savetxt(tmp_path / f"view{k}.scf", d)
    frames = load_landmark_folder(tmp_path)
    assert [f.landmarks.tolist() for f in frames] == [[1, 2, 3], [0, 2, 3], [0, 1, 3]]
    np.testing.assert_allclose(frames[1].keypoints, pts[[0, 2, 3]])
    np.testing.assert_allclose(frames[2].descriptors, np.arange(20.0).reshape(4, 5)[[0, 1, 3]] + 2)
    assert [f.landmarks.tolist() for f in load_landmark_folder(tmp_path, "sift")][0] == [1, 2, 3]
    bad = pts.copy()
    bad[1, 0] = np.nan
    np.savetxt(tmp_path / "view0.txt", bad)
    with pytest.raises(InputError, match="row 2 is \\[nan, 20.0\\].*'nan nan'"):
        load_landmark_folder(tmp_path)
    np.savetxt(tmp_path / "view0.txt", np.full((4, 2), np.nan))
    with pytest.raises(InputError, match="sees none of them"):
        load_landmark_folder(tmp_path)


def test_descriptors_of_the_seen_landmarks_only_are_refused_naming_the_nan_rows(tmp_path):
    """An image that does not see a landmark, with a descriptor file of a row per landmark it
    sees: refused as "3 descriptor rows for 4 landmarks of view1.png", though view1.png sees
    3; the message now says its 'nan nan' row needs a descriptor row too."""
    pts = np.array([[10.0, 12.0], [30.0, 20.0], [50.0, 40.0], [20.0, 30.0]])
    for k in range(2):
        _image(tmp_path / f"view{k}.png")
        rows = pts.copy()
        if k:
            rows[2] = np.nan
        np.savetxt(tmp_path / f"view{k}.txt", rows)
        np.savetxt(tmp_path / f"view{k}.scf", np.ones((4 - k, 5)))
    with pytest.raises(InputError) as err:
        load_landmark_folder(tmp_path)
    assert str(err.value) == (
        f"{tmp_path / 'view1.scf'}: 3 descriptor rows for the 4 label rows of view1.txt; "
        "view1.png sees 3 landmarks, but each of its 1 'nan nan' label rows needs a "
        "descriptor row too (any numbers: it is not read)")


def test_a_minus_one_row_is_refused_naming_the_nan_row(tmp_path):
    """'-1 -1', how other tools mark a landmark an image does not see, was refused only as a
    label outside the image to fix; the error now names 'nan nan', this format's mark. A
    label that is merely off the image gets no such hint."""
    pts = np.array([[10.0, 12.0], [30.0, 20.0], [50.0, 40.0]])
    for k in range(2):
        _image(tmp_path / f"view{k}.png")
        np.savetxt(tmp_path / f"view{k}.txt", pts)
    rows = pts.copy()
    rows[1] = -1
    np.savetxt(tmp_path / "view1.txt", rows)
    with pytest.raises(InputError, match=r"row 2 at \[-1.0, -1.0\] lies outside the 64x48 "
                       r"image view1.png; .*write the row 'nan nan' \(not -1 -1\)$"):
        load_landmark_folder(tmp_path, descriptors="sift")
    rows[1] = [-3, 20]
    np.savetxt(tmp_path / "view1.txt", rows)
    with pytest.raises(InputError, match=r"y down\)$"):
        load_landmark_folder(tmp_path, descriptors="sift")


def test_one_file_of_negative_descriptors_among_histograms_is_warned(tmp_path, caplog):
    """One negative value in one of the descriptor files switched every image from chi-square
    to L2 distance with no word but the stage line's "vector descriptors"; it is now warned,
    naming the file."""
    pts = np.array([[10.0, 12.0], [30.0, 20.0], [50.0, 40.0]])
    for k in range(3):
        _image(tmp_path / f"view{k}.png")
        np.savetxt(tmp_path / f"view{k}.txt", pts + k)
        d = np.arange(15.0).reshape(3, 5) + k
        if k == 1:
            d[2, 4] = -0.5
        np.savetxt(tmp_path / f"view{k}.scf", d)
    with caplog.at_level("WARNING"):
        frames = load_landmark_folder(tmp_path)
    assert {f.descriptor_kind for f in frames} == {"vector"}
    assert "1 of 3 descriptor files hold negative values (view1.scf)" in caplog.text
    assert "compared by L2 distance, not chi-square" in caplog.text


def test_two_images_of_one_name_are_refused_not_given_one_keypoint_file(tmp_path):
    """view0.png and view0.jpg (a converted copy) both paired with view0.txt by name: the same
    labels on two cameras, one view counted twice; refused naming both images and the file."""
    pts = np.array([[10.0, 12.0], [30.0, 20.0], [50.0, 40.0]])
    for k in range(3):
        _image(tmp_path / f"view{k}.png")
        np.savetxt(tmp_path / f"view{k}.txt", pts + k)
    Image.open(tmp_path / "view0.png").convert("RGB").save(tmp_path / "view0.jpg")
    with pytest.raises(InputError, match=r"view0\.jpg and view0\.png are both images of the "
                                         r"keypoint file view0\.txt"):
        load_landmark_folder(tmp_path, descriptors="sift")


def test_natural_order_does_not_depend_on_the_listing_order():
    """Names of one number and one text but for zeros or case (v1, v01, V1) tied, and kept
    the order the folder listed them in: the cameras' order, and with it the ring and seq:K
    graphs and the pairing by order, changed with the file system."""
    names = ["v1.png", "v01.png", "V1.png", "v2.png"]
    assert sorted(names, key=natural_key) == sorted(names[::-1], key=natural_key)
    assert sorted(names, key=natural_key)[-1] == "v2.png"
