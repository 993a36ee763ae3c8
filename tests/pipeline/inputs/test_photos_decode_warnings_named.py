"""Pillow's warnings while a photograph is DECODED (after its header: a TIFF whose EXIF block
lies past the file's end, 'UserWarning: Corrupt EXIF data. Expecting to read 2 bytes but only
got 0'; a page above Pillow's decompression-bomb limit, 'DecompressionBombWarning: Image size
… could be decompression bomb DOS attack') reached the user raw, naming Pillow's source and
not the file; they are now one warning of ours naming the file, as the header's are
(test_photos_damaged_header_named.py)."""

import logging
import struct
import warnings

import numpy as np
from PIL import Image

import pipeline.inputs.photos as photos
from pipeline.inputs.photos import load_folder, load_image


def _tiff_with_exif_past_the_end(path, w=80, h=64):
    """An uncompressed 8-bit RGB TIFF whose first IFD names an EXIF IFD 10,000 bytes past the
    file's end: its header reads, Pillow reads the EXIF IFD while it decodes."""
    pix = np.random.default_rng(0).integers(0, 255, (h, w, 3), dtype=np.uint8).tobytes()
    n, ifd = 11, 8
    bps = ifd + 2 + 12 * n + 4
    start = bps + 6
    entries = [(256, 4, 1, w), (257, 4, 1, h), (258, 3, 3, bps), (259, 3, 1, 1),
               (262, 3, 1, 2), (273, 4, 1, start), (277, 3, 1, 3), (278, 4, 1, h),
               (279, 4, 1, len(pix)), (284, 3, 1, 1), (34665, 4, 1, start + len(pix) + 10_000)]
    path.write_bytes(b"II*\0" + struct.pack("<IH", ifd, n)
                     + b"".join(struct.pack("<HHII", *e) for e in entries)
                     + struct.pack("<I", 0) + struct.pack("<HHH", 8, 8, 8) + pix)
    return pix


def _load(path, caplog):
    logging.getLogger("pipeline.inputs.photos").setLevel(logging.WARNING)
    with warnings.catch_warnings(record=True) as seen, caplog.at_level(logging.WARNING):
        warnings.simplefilter("always")
        pixels, header = load_image(path)
    header.close()
    lines = [r.getMessage() for r in caplog.records if path.name in r.getMessage()]
    return pixels, [f"{w.category.__name__}: {w.message}" for w in seen], lines


def test_a_damaged_exif_block_met_while_decoding_is_one_warning_naming_the_file(tmp_path,
                                                                                caplog):
    path = tmp_path / "frame.tif"
    pix = _tiff_with_exif_past_the_end(path)
    pixels, raw, lines = _load(path, caplog)
    assert raw == []
    assert lines == ["warning: frame.tif: decoding it, Pillow warned: Corrupt EXIF data. "
                     "Expecting to read 2 bytes but only got 0; the image as decoded is used"]
    assert pixels.tobytes() == pix  # the pixels as they are


def test_a_decompression_bomb_warning_while_decoding_names_the_file(tmp_path, caplog,
                                                                    monkeypatch):
    # Pillow's limit lowered to 3,000 pixels stands for a photo of 90-100 M pixels: under
    # MAX_IMAGE_PIXELS (the header is read), above Pillow's own limit while decoding
    path = tmp_path / "big.tif"
    Image.fromarray(np.zeros((64, 80, 3), np.uint8)).save(path)
    monkeypatch.setattr(Image, "MAX_IMAGE_PIXELS", 3000)
    pixels, raw, lines = _load(path, caplog)
    assert raw == [] and pixels.shape == (64, 80, 3)
    assert len(lines) == 1 and lines[0].startswith(
        "warning: big.tif: decoding it, Pillow warned: Image size (5120 pixels) exceeds limit "
        "of 3000 pixels, could be decompression bomb DOS attack; the image as decoded is used")


def test_a_warning_not_of_pillow_goes_through_as_it_was(tmp_path, caplog, monkeypatch):
    path = tmp_path / "plain.tif"
    Image.fromarray(np.zeros((64, 80, 3), np.uint8)).save(path)
    real = photos._pixels

    def warning_pixels(im):
        warnings.warn("not Pillow's", RuntimeWarning, stacklevel=1)
        return real(im)

    monkeypatch.setattr(photos, "_pixels", warning_pixels)
    _, raw, lines = _load(path, caplog)
    assert raw == ["RuntimeWarning: not Pillow's"] and lines == []


def test_a_folder_with_such_a_photo_says_it_once(tmp_path, caplog):
    for name in ("a.tif", "b.tif"):
        Image.fromarray(np.random.default_rng(1).integers(0, 255, (64, 80, 3), np.uint8)
                        ).save(tmp_path / name)
    _tiff_with_exif_past_the_end(tmp_path / "c.tif")
    logging.getLogger("pipeline.inputs.photos").setLevel(logging.WARNING)
    with warnings.catch_warnings(record=True) as seen, caplog.at_level(logging.WARNING):
        warnings.simplefilter("always")
        views = load_folder(tmp_path)
    assert [v.name for v in views] == ["a.tif", "b.tif", "c.tif"]
    assert [str(w.message) for w in seen] == []
    assert [r.getMessage() for r in caplog.records if "Pillow" in r.getMessage()] == [
        "warning: c.tif: decoding it, Pillow warned: Corrupt EXIF data. Expecting to read 2 "
        "bytes but only got 0; the image as decoded is used"]
