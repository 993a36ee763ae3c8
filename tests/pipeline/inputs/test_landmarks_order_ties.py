"""Files paired by natural name order (the CMU hotel's layout) whose names tie in that order:
a copy 'seq01' beside 'seq1' (or 'Seq1', or a label file 'lab02' beside 'lab2') was ordered
by the tie-break on the name, and every later image took the next image's label file, with
no word (the scores, identity on the label rows, stayed perfect)."""

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from pipeline.errors import InputError
from pipeline.inputs.landmarks import load_landmark_folder

PTS = np.array([[10.0, 12.0], [30.0, 20.0], [50.0, 40.0]])


def _folder(path: Path, images, labels) -> Path:
    path.mkdir()
    for k, name in enumerate(images):
        Image.new("L", (64, 48), 40 * k).save(path / name)
    for k, name in enumerate(labels):
        np.savetxt(path / name, PTS + k)
    return path


@pytest.mark.parametrize("images, labels, tie", [
    (["v.seq0.png", "v.seq1.png", "v.seq01.png"], ["lab1.txt", "lab2.txt", "lab3.txt"],
     "v.seq01.png and v.seq1.png tie in natural name order .* the images pair by that order"),
    (["v.seq0.png", "v.seq1.png", "V.seq1.png"], ["lab1.txt", "lab2.txt", "lab3.txt"],
     "V.seq1.png and v.seq1.png tie"),
    (["v.seq0.png", "v.seq1.png", "v.seq2.png"], ["lab1.txt", "lab2.txt", "lab02.txt"],
     "lab02.txt and lab2.txt tie in natural name order .* the keypoint files pair by that "
     "order")])
def test_names_that_tie_in_natural_order_are_refused_when_files_pair_by_order(
        tmp_path, images, labels, tie):
    folder = _folder(tmp_path / "set", images, labels)
    with pytest.raises(InputError, match=tie):
        load_landmark_folder(folder, descriptors="sift")


def test_the_same_names_paired_by_name_are_read(tmp_path):
    # named after their images, the files need no order: a copy is one more image
    folder = _folder(tmp_path / "set", ["v.seq1.png", "v.seq01.png"],
                     ["v.seq01.txt", "v.seq1.txt"])
    frames = load_landmark_folder(folder, descriptors="sift")
    assert [(f.name, f.keypoint_file) for f in frames] == [("v.seq01.png", "v.seq01.txt"),
                                                           ("v.seq1.png", "v.seq1.txt")]
