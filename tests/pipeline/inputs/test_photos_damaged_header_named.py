"""A photograph whose header is damaged (a TIFF's tag count, an EXIF block) printed Pillow's
own 'UserWarning: Corrupt EXIF data. Expecting to read 12 bytes but only got …' lines, once
per damaged entry, in the middle of run-images' output; it is now one warning of ours naming
the file."""

import logging
import warnings

import numpy as np
from PIL import Image

from pipeline.inputs.photos import open_header


def test_a_damaged_tiff_header_is_one_warning_naming_the_file(tmp_path, caplog):
    path = tmp_path / "frame.tif"
    Image.fromarray(np.zeros((20, 30, 3), np.uint8)).save(path, description="a description")
    data = bytearray(path.read_bytes())
    data[8] ^= 0xFF      # the first IFD's entry count: entries past the file's end
    path.write_bytes(bytes(data))
    logging.getLogger("pipeline.inputs.photos").setLevel(logging.WARNING)
    with warnings.catch_warnings(record=True) as seen, caplog.at_level(logging.WARNING):
        warnings.simplefilter("always")
        im = open_header(path)
    im.close()
    assert [str(w.message) for w in seen] == []
    lines = [r.getMessage() for r in caplog.records if "frame.tif" in r.getMessage()]
    assert len(lines) == 1 and "its header is damaged (Pillow: Corrupt EXIF data" in lines[0]
