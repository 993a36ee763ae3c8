"""pipeline.inputs.photos: deep (16-bit, float) pixels stretched to 8 bits, whatever a few
hot or saturated pixels hold."""

import numpy as np
from PIL import Image

from pipeline.inputs.photos import load_folder


def _texture(h, w, seed):
    rng = np.random.default_rng(seed)
    return rng.random((h, w))


def test_one_hot_pixel_does_not_blacken_10_bit_data(tmp_path):
    # 10-bit data in a 16-bit PNG, one pixel saturated at 65535 (a hot pixel): stretched to
    # the maximum, every other pixel fell below 5 of 255 and the detector found nothing
    d = tmp_path / "imgs"
    d.mkdir()
    for k in range(2):
        deep = (_texture(60, 80, k) * 1023).astype(np.uint16)
        deep[3, 5] = 65535
        Image.fromarray(deep).save(d / f"f{k}.png")
    for v in load_folder(d):
        img = v.image.astype(np.int64)
        assert img[3, 5] == 255
        rest = np.delete(img.ravel(), 3 * 80 + 5)
        assert np.percentile(rest, 99) > 200 and rest.std() > 50  # the whole range is used


def test_float_image_with_one_huge_value_keeps_its_contrast(tmp_path):
    d = tmp_path / "imgs"
    d.mkdir()
    for k in range(2):
        a = _texture(60, 80, k).astype(np.float32)
        a[0, 0] = 1e6
        Image.fromarray(a, mode="F").save(d / f"f{k}.tif")
    for v in load_folder(d):
        assert v.image.std() > 50


def test_dark_image_with_a_few_bright_pixels_keeps_them():
    # content in fewer pixels than the percentile leaves out: the maximum is then the scale
    from pipeline.inputs.photos import _to_uint8

    a = np.zeros((100, 100), np.uint16)
    a[0, :3] = [1000, 2000, 4000]
    out = _to_uint8(a)
    assert out[0, :3].tolist() == [64, 128, 255] and out.sum() == 64 + 128 + 255
