"""pipeline.inputs.photos: 16-bit colour PNG and TIFF files are read from all 16 bits (Pillow
keeps each sample's high byte, so 10-bit colour data came out at 0..3 of 255: no feature)."""

import cv2
import numpy as np
import pytest

from pipeline.inputs.photos import load_folder, load_image


def _texture(h, w, seed):
    rng = np.random.default_rng(seed)
    return rng.random((h, w, 3))


@pytest.mark.parametrize("suffix", [".png", ".tif"])
@pytest.mark.parametrize("alpha", [False, True], ids=["rgb", "rgba"])
def test_10_bit_colour_in_16_bits_keeps_its_contrast(tmp_path, suffix, alpha):
    d = tmp_path / "imgs"
    d.mkdir()
    for k in range(2):
        rgb = (_texture(40, 60, k) * 1023).astype(np.uint16)
        bgr = rgb[..., ::-1]
        if alpha:
            bgr = np.dstack([bgr, np.full((40, 60), 1023, np.uint16)])
        assert cv2.imwrite(str(d / f"f{k}{suffix}"), bgr)
    for k, v in enumerate(load_folder(d)):
        assert v.image.dtype == np.uint8 and v.image.shape == (40, 60, 3)
        assert np.percentile(v.image, 99) > 200 and v.image.std() > 50
        stored = (_texture(40, 60, k) * 1023).astype(np.uint16)  # in RGB order
        assert np.corrcoef(v.image.ravel(), stored.ravel())[0, 1] > 0.999


def test_channel_order_is_rgb(tmp_path):
    rgb = np.zeros((20, 30, 3), np.uint16)
    rgb[..., 0] = 1000  # red only
    rgb[5:10, 5:10, 0] = 200
    path = tmp_path / "red.png"
    assert cv2.imwrite(str(path), rgb[..., ::-1])
    pixels, _ = load_image(path)
    assert pixels[..., 0].max() == 255 and pixels[..., 1:].max() == 0


def test_8_bit_colour_is_read_as_before(tmp_path):
    rgb = (_texture(20, 30, 0) * 255).astype(np.uint8)
    path = tmp_path / "c.png"
    assert cv2.imwrite(str(path), rgb[..., ::-1])
    pixels, _ = load_image(path)
    assert np.array_equal(pixels, rgb)
