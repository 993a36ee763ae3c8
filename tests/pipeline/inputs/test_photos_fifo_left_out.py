"""A FIFO named like a photograph (``x.jpg``) in a photo folder was left out without a word,
though every other entry that looks like a photograph and is not read is warned."""

import os

import pytest
from noise_photos import noise_photos

from pipeline.errors import InputError
from pipeline.inputs.photos import load_folder


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs on this system")
def test_a_fifo_named_like_a_photograph_is_warned(tmp_path, caplog):
    d = tmp_path / "photos"
    noise_photos(d, ["p0.jpg", "p1.jpg"])
    os.mkfifo(d / "x.jpg")
    os.mkfifo(d / "pipe")  # not named like a photograph: skipped as other files are
    with caplog.at_level("WARNING", logger="pipeline"):
        assert [v.name for v in load_folder(d, max_size=None)] == ["p0.jpg", "p1.jpg"]
    assert [r.getMessage() for r in caplog.records if r.levelname == "WARNING"] == [
        f"warning: {str(d)!r}: 1 entry(ies) named like images but not regular files (a FIFO, "
        "device or socket) left out (x.jpg; give the photographs as files)"]
    (d / "p1.jpg").unlink()
    with pytest.raises(InputError, match=r"only one image .*p0\.jpg.*x\.jpg"):
        load_folder(d, max_size=None)
