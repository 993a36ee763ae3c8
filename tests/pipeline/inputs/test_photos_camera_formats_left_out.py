"""A phone's HEIC photographs (or a camera's raw files) beside its JPEGs were left out with an
info line only, hidden by --quiet, though README promises a warning for every photograph
of another format left out: Pillow does not open them, so they were not among the formats
it registers. They are now warned as the others are."""

import pytest
from noise_photos import noise_photos

from pipeline.errors import InputError
from pipeline.inputs.photos import load_folder

#: the first bytes of an iPhone's HEIC file (its ISO-BMFF 'ftyp' box)
HEIC_HEAD = b"\x00\x00\x00\x18ftypheic\x00\x00\x00\x00mif1heic"


def _jpegs(d, n=2):
    noise_photos(d, [f"p{k}.jpg" for k in range(n)])


def _warned(caplog):
    return [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]


def test_heic_and_raw_files_beside_the_photographs_are_warned(tmp_path, caplog):
    d = tmp_path / "phone"
    _jpegs(d)
    (d / "IMG_0001.HEIC").write_bytes(HEIC_HEAD)
    (d / "IMG_0002.dng").write_bytes(b"II*\x00\x08\x00\x00\x00")
    (d / "notes.txt").write_text("not a photograph")
    with caplog.at_level("WARNING", logger="pipeline"):
        assert [v.name for v in load_folder(d, max_size=None)] == ["p0.jpg", "p1.jpg"]
    assert _warned(caplog) == [
        f"warning: {str(d)!r}: 2 image file(s) of a format not read here left out "
        "(IMG_0001.HEIC, IMG_0002.dng; convert them to one of .jpg, .jpeg, .jfif, .jpe, .png, "
        ".tif, .tiff, .bmp, .webp)"]


def test_a_folder_of_heic_files_only_is_warned_before_it_is_refused(tmp_path, caplog):
    d = tmp_path / "phone"
    d.mkdir()
    (d / "IMG_0001.heic").write_bytes(HEIC_HEAD)
    (d / "IMG_0002.heic").write_bytes(HEIC_HEAD)
    with caplog.at_level("WARNING", logger="pipeline"), \
            pytest.raises(InputError, match=r"^no images in .*found 2 other file"):
        load_folder(d)
    assert len(_warned(caplog)) == 1 and "IMG_0001.heic, IMG_0002.heic;" in _warned(caplog)[0]


def test_a_heic_file_named_jpg_is_named_as_heic(tmp_path):
    """A phone's HEIC photo renamed .jpg (by a transfer tool) was refused as "a truncated or
    non-image file"; the error now says what it is."""
    from pipeline.inputs.photos import load_image

    path = tmp_path / "IMG_0004.jpg"
    path.write_bytes(HEIC_HEAD + bytes(64))
    with pytest.raises(InputError) as err:
        load_image(path)
    assert str(err.value) == (
        "IMG_0004.jpg: a HEIC/HEIF image (brand 'heic' in its header), whatever its suffix "
        "says; this reader does not decode HEIC: convert it to JPEG (e.g. magick IMG_0004.jpg "
        "IMG_0004-converted.jpg), or export the photos from the phone as JPEG")
