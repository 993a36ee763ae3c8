"""A render-cache entry with a changed byte in a zip or array header is a bad entry, ignored
and written again: zipfile and numpy raise NotImplementedError, RuntimeError or tokenize's
TokenError there, which escaped the cache and ended run-formation with a traceback."""

import io
import zipfile

import numpy as np
import pytest

import data_synth
from data_synth import cache

SIZE = (96, 72)


def _central_entry(data: bytes, name: bytes) -> int:
    """Offset of the zip central directory header of member ``name``."""
    return next(i for i in range(len(data)) if data[i:i + 4] == b"PK\x01\x02"
                and data[i + 46:i + 46 + len(name)] == name)


def _damage(data: bytes, how: str) -> bytes:
    data = bytearray(data)
    with zipfile.ZipFile(io.BytesIO(bytes(data))) as z:
        info = z.getinfo("image.npy")
    if how == "compression":  # the central directory's compression method: unknown
        data[_central_entry(data, b"image.npy") + 10] = 99
    elif how == "encrypted":  # the central directory's flags: "encrypted"
        data[_central_entry(data, b"depth.npy") + 8] |= 1
    else:  # the array header's shape loses its closing parenthesis
        start = info.header_offset + 30 + len(b"image.npy")
        end = data.index(b")", start)
        data[end] = ord(" ")
    return bytes(data)


@pytest.mark.parametrize("how", ["compression", "encrypted", "array-header"])
def test_a_damaged_header_is_a_bad_entry_not_a_traceback(tmp_path, monkeypatch, how):
    monkeypatch.setenv(cache.ENV, str(tmp_path / "cache"))
    fresh = data_synth.render("d", seed=2, size=SIZE)
    path = cache.entry_path(2, SIZE, 6)
    path.write_bytes(_damage(path.read_bytes(), how))
    assert cache.load_views(2, SIZE, 6) is None
    one = cache.load_view(2, SIZE, 6, 1)  # read at its offsets: a flag alone changes nothing
    assert one is None or one["image"].tobytes() == fresh.views[1].image.tobytes()
    cache.prune(path.parent, limit=10**12)
    again = data_synth.render("d", seed=2, size=SIZE)  # rendered and written again
    for a, b in zip(fresh.views, again.views, strict=True):
        np.testing.assert_array_equal(a.image, b.image)
    assert cache.load_views(2, SIZE, 6) is not None
