"""Label tables whose names carry no .txt (the CMU house sequence's labels are 'house1',
'house2', ...): the folder was refused as '5 images but 0 keypoint files', with no word of
the five tables beside the images; the message now names them and says to rename them."""

import numpy as np
import pytest
from PIL import Image

from pipeline.errors import InputError
from pipeline.inputs.landmarks import load_landmark_folder


def test_label_tables_without_the_txt_suffix_are_named(tmp_path):
    pts = np.array([[10.0, 12.0], [30.0, 20.0], [50.0, 40.0]])
    for k in range(5):
        Image.new("L", (64, 48), 40 * k).save(tmp_path / f"house.seq{k}.png")
        np.savetxt(tmp_path / f"house{k + 1}", pts + k)
    (tmp_path / "README").write_text("CMU house: 5 frames\n")  # no table: not named
    with pytest.raises(InputError, match=r"5 images but 0 keypoint files .*; 5 file\(s\) hold "
                                         r"rows 'x y' but are not named .txt \(house1, house2, "
                                         r"house3 and 2 more\): keypoint files are read as "
                                         r"NAME.txt, so rename them; give each image"):
        load_landmark_folder(tmp_path, descriptors="sift")
