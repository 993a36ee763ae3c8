"""A photograph whose EXIF block is damaged printed Pillow's own 'UserWarning: Corrupt EXIF
data. Expecting to read 2 bytes but only got 0' lines in the middle of run-images' output; the
tags Pillow could read still serve (or none do), without the lines."""

import io
import warnings

import numpy as np
from PIL import ExifTags, Image

from pipeline.inputs.photos import exif_focal_px


def _damaged_exif_jpeg() -> bytes:
    im = Image.fromarray(np.zeros((40, 60, 3), np.uint8))
    ex = Image.Exif()
    ex[ExifTags.Base.Make] = "Cam"
    ex.get_ifd(ExifTags.IFD.Exif)[ExifTags.Base.FocalLengthIn35mmFilm] = 28
    buf = io.BytesIO()
    im.save(buf, "JPEG", exif=ex.tobytes())
    data = bytearray(buf.getvalue())
    data[data.find(b"Exif\x00\x00") + 36] ^= 0xFF   # a byte of the EXIF sub-IFD's entry
    return bytes(data)


def test_a_damaged_exif_block_prints_no_warning():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        header = Image.open(io.BytesIO(_damaged_exif_jpeg()))
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        assert exif_focal_px(header, 60, 40) is None
    assert [str(w.message) for w in seen] == []
