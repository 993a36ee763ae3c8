"""A folder of labelled sets (one sub-folder per object class, as benchmarks ship them) given
as DIR was refused as 'found 0 image(s)' without a word of the sub-folders, and an image file
given as DIR as 'no such folder'; the messages now name the sub-folders that hold images, and
say that the file is not a folder."""

import numpy as np
import pytest
from PIL import Image

from pipeline.errors import InputError
from pipeline.inputs.landmarks import load_landmark_folder


def write_set(folder):
    folder.mkdir(parents=True)
    for k in range(2):
        Image.fromarray(np.full((20, 30), 40 * k, np.uint8)).save(folder / f"im{k}.png")
        np.savetxt(folder / f"im{k}.txt", [[3.0, 4.0], [10.0, 12.0]])


def test_a_folder_of_labelled_sets_names_them(tmp_path):
    for name in ("Car", "Duck"):
        write_set(tmp_path / "classes" / name)
    with pytest.raises(InputError, match=r"found 0 image\(s\).*sub-folder\(s\) Car, Duck hold "
                                         r"images: give one of them"):
        load_landmark_folder(tmp_path / "classes")


def test_an_image_given_as_the_folder_is_named_as_a_file(tmp_path):
    write_set(tmp_path / "set")
    with pytest.raises(InputError, match=r"im0.png: a file, not a folder; give the folder"):
        load_landmark_folder(tmp_path / "set" / "im0.png")
