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


def _turned_warnings(caplog):
    return [r.getMessage() for r in caplog.records if "turned a quarter" in r.getMessage()]


def test_k_txt_beside_files_turned_a_quarter_is_warned(tmp_path, caplog):
    """A K.txt of 320x240 landscape photos beside portrait (240x320) files: its principal
    point lies inside them and within the off-centre tolerance, so it was taken without a
    word, and the fixed principal point then tripled the reprojection error."""
    from pipeline.inputs.photos import load_folder

    d = tmp_path / "photos"
    d.mkdir()
    rng = np.random.default_rng(0)
    for name, (h, w) in (("a.png", (240, 320)), ("b.png", (320, 240)), ("c.png", (320, 240))):
        Image.fromarray(rng.integers(0, 255, (h, w, 3), dtype=np.uint8)).save(d / name)
    (d / "K.txt").write_text("300 0 159.5\n0 300 119.5\n0 0 1\n")
    with caplog.at_level("WARNING", logger="pipeline"):
        load_folder(d, max_size=None)
    assert _turned_warnings(caplog) == [
        f"warning: {d / 'K.txt'}: principal point (159.5, 119.5) lies near the centre of the "
        "image turned a quarter, not of the image, for 2 image(s): b.png (240x320), c.png "
        "(240x320); their pixels are turned against K.txt's camera (one K serves every image, "
        "and the EXIF orientation tag is not applied): turn those files to K.txt's "
        "orientation, or run them apart with a K.txt of their own (fx, fy and cx, cy swapped)"]
    assert not [r for r in caplog.records if "lies far from the centre" in r.getMessage()]
