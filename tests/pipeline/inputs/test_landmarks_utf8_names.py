"""Labelled images whose file names are not UTF-8 (Latin-1 names from an old archive) were
read, and report.json named them with lone surrogate escapes ('v\\udce90.png') that JSON
readers such as jq turn into U+FFFD, so the report named images that do not exist; the folder
is now refused as run-images refuses it, naming the files and how to rename them."""

import numpy as np
import pytest
from PIL import Image

from pipeline.errors import InputError
from pipeline.inputs.landmarks import load_landmark_folder


def test_image_names_that_are_not_utf8_are_refused(tmp_path):
    for k in range(2):
        stem = b"v\xe9%d" % k
        name = stem.decode("utf-8", "surrogateescape")
        Image.fromarray(np.full((20, 30), 40 * k, np.uint8)).save(tmp_path / f"{name}.png")
        np.savetxt(tmp_path / f"{name}.txt", [[3.0, 4.0], [10.0, 12.0]])
    with pytest.raises(InputError, match=r"2 image file name\(s\) in .* are not UTF-8 text "
                                         r".*rename them"):
        load_landmark_folder(tmp_path)
