"""One camera read alone from the render cache (a robot process) is checked as the whole
entry is: a byte changed on disk in its pixels or depth gives no view, never a wrong one."""

import numpy as np
import pytest

import data_synth
from data_synth import cache

SIZE = (96, 72)


@pytest.mark.parametrize("where", [0.3, 0.6, 0.9])
def test_a_flipped_byte_in_one_camera_is_not_read_as_its_view(tmp_path, monkeypatch, where):
    monkeypatch.setenv(cache.ENV, str(tmp_path / "cache"))
    fresh = data_synth.render("d", seed=2, size=SIZE)
    path = cache.entry_path(2, SIZE, 6)
    data = bytearray(path.read_bytes())
    data[int(len(data) * where)] ^= 0xFF  # inside the pixels or the depth of one camera
    path.write_bytes(bytes(data))
    for i in range(6):
        one = cache.load_view(2, SIZE, 6, i)
        assert one is None or (one["image"].tobytes() == fresh.views[i].image.tobytes()
                               and one["depth"].tobytes() == fresh.views[i].depth.tobytes()), i
        view, _ = data_synth.render_robot(i, "d", seed=2, size=SIZE)
        np.testing.assert_array_equal(view.image, fresh.views[i].image)
        np.testing.assert_array_equal(view.depth, fresh.views[i].depth)
    assert sum(cache.load_view(2, SIZE, 6, i) is None for i in range(6)) == 1  # that camera only
