"""An empty homography file (--truth homographies) printed numpy's own warning ('UserWarning:
loadtxt: input contained no data') above the error that names the file; the error alone now
speaks."""

import warnings

import numpy as np
import pytest

from pipeline.errors import InputError
from pipeline.evaluation.truth import read_homographies


def test_an_empty_homography_file_is_one_error_and_no_warning(tmp_path):
    (tmp_path / "H1to2p.txt").write_text("")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # any warning fails the test
        with pytest.raises(InputError, match=r"H1to2p.txt: expected an invertible 3 x 3 "
                                             r"homography, got shape \(0,\)"):
            read_homographies(tmp_path, 2)


def test_a_homography_file_is_read(tmp_path):
    np.savetxt(tmp_path / "H1to2p.txt", np.diag([2.0, 2.0, 1.0]))
    H = read_homographies(tmp_path, 2)
    assert np.allclose(H[0], np.eye(3)) and H.shape == (2, 3, 3)
