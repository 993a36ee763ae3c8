"""A K.txt's skew ``K[0, 1]`` was accepted unbounded (1e9, or cx written where the skew goes)
and used by matching and fusion while the COLMAP stages, whose pinhole has no skew, left it
out; more than MAX_SKEW_FRACTION (0.1) x fx is now an InputError naming the value, and a
calibration's small skew is kept."""

import pytest

from pipeline.errors import InputError
from pipeline.inputs.photos import read_k_txt


def _k(tmp_path, skew, fx=800.0):
    path = tmp_path / "K.txt"
    path.write_text(f"{fx} {skew} 320\n0 {fx} 240\n0 0 1\n")
    return path


@pytest.mark.parametrize(("skew", "shown"), [("1e9", r"1e\+09 is 1.25e\+06 x fx \(800\)"),
                                             ("320", r"320 is 0.4 x fx \(800\)"),
                                             ("-80.5", r"-80.5 is 0.101 x fx \(800\)")])
def test_a_skew_beyond_a_tenth_of_fx_is_refused(tmp_path, skew, shown):
    path = _k(tmp_path, skew)
    with pytest.raises(InputError, match=rf"^intrinsics file '{path}': skew K\[0, 1\] = "
                                         rf"{shown}; a camera's skew is 0 .* at most 0.1 x fx "
                                         r"is accepted"):
        read_k_txt(path)


@pytest.mark.parametrize("skew", [0.0, 0.5, -3.25, 80.0, -80.0])
def test_a_skew_up_to_a_tenth_of_fx_is_kept(tmp_path, skew):
    assert read_k_txt(_k(tmp_path, skew))[0, 1] == skew
