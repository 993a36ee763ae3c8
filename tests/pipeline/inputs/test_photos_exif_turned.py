"""The EXIF focal-plane route on pixels turned a quarter after capture: the focal length in
pixels does not change with a rotation, so a portrait copy of a landscape photograph (EXIF
block kept, ExifImageWidth still the sensor's width) keeps the landscape's focal length."""

import numpy as np
import pytest
from PIL import ExifTags, Image

from pipeline.inputs.photos import exif_focal_px


def _jpeg(path, w, h, **tags):
    exif = Image.Exif()
    exif.get_ifd(ExifTags.IFD.Exif).update(
        {getattr(ExifTags.Base, k).value: v for k, v in tags.items()})
    Image.fromarray(np.zeros((h, w, 3), np.uint8)).save(path, exif=exif)


# 5 mm lens, 200 px per mm on a 800 x 600 sensor: 1000 px at the sensor's resolution
TAGS = dict(FocalLength=5.0, FocalPlaneXResolution=200.0, FocalPlaneResolutionUnit=4,
            ExifImageWidth=800, ExifImageHeight=600)


@pytest.mark.parametrize("w, h, expected", [
    (800, 600, 1000.0),   # as captured
    (600, 800, 1000.0),   # turned a quarter
    (400, 300, 500.0),    # resized to half
    (300, 400, 500.0),    # resized to half and turned
])
def test_a_turned_copy_keeps_its_focal_length(tmp_path, w, h, expected):
    path = tmp_path / "p.jpg"
    _jpeg(path, w, h, **TAGS)
    with Image.open(path) as im:
        f, source = exif_focal_px(im, w, h)
    assert source == "exif-focal-plane" and f == pytest.approx(expected, rel=1e-9)
