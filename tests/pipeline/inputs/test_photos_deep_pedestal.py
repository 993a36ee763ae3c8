"""16-bit pixels on a pedestal (a thermal camera's counts, 7000 to 8000 of 65535; a sensor's
black level) were stretched from 0, so the content kept an eighth of the 8-bit range: on
Sceaux photographs so stored SIFT found 44 features an image instead of 750, and nothing
registered. The stretch now starts at the low percentile, as it ends at the high one."""

import numpy as np
import pytest
from PIL import Image

from pipeline.inputs.photos import _to_uint8, load_folder


def test_data_on_a_pedestal_fills_the_8_bit_range(tmp_path):
    d = tmp_path / "thermal"
    d.mkdir()
    rng = np.random.default_rng(0)
    for k in range(2):
        Image.fromarray((7000 + rng.random((60, 80)) * 1000).astype(np.uint16)).save(
            d / f"t{k}.png")
    for v in load_folder(d, max_size=None):
        assert np.percentile(v.image, 1) < 10 and np.percentile(v.image, 99) > 245
        assert v.image.std() > 60  # uniform noise over 0..255: std 74


@pytest.mark.parametrize("offset", [0, 7000, -500])
def test_the_stretch_maps_the_percentiles_to_0_and_255(offset):
    a = (np.arange(100 * 100).reshape(100, 100) + offset).astype(np.float32)
    out = _to_uint8(a).astype(np.int64)
    assert out.min() == 0 and out.max() == 255
    # a linear map: the middle value lands in the middle, within one grey level
    assert abs(int(out.ravel()[5000]) - 127.5) <= 1.0


def test_a_flat_pedestal_with_a_few_warmer_pixels_keeps_them():
    a = np.full((100, 100), 7000, np.uint16)
    a[0, :3] = [7250, 7500, 8000]
    out = _to_uint8(a)
    assert out[0, :3].tolist() == [64, 128, 255] and out.sum() == 64 + 128 + 255


def test_a_float_image_masked_with_nan_keeps_its_contrast():
    """A float image (thermal or depth) with a NaN mask over a third of it: the NaN pixels
    counted as 0 in the percentiles, and its values at 7000-8000 were squeezed again."""
    rng = np.random.default_rng(1)
    a = (7000 + rng.random((60, 90)) * 1000).astype(np.float32)
    a[:, :30] = np.nan
    a[0, 40] = np.inf
    out = _to_uint8(a)
    assert (out[:, :30] == 0).all() and out[0, 40] == 0
    assert out[1:, 30:].std() > 60 and np.percentile(out[1:, 30:], 99) > 245
