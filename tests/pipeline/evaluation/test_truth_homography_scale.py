"""A homography file is read up to scale: the same H at a tiny scale is not singular."""

import numpy as np
import pytest

from pipeline.errors import InputError
from pipeline.evaluation.truth import apply_homography, pair_homography, read_homographies

H = np.array([[0.9, 0.05, 12.0], [-0.03, 1.1, -7.5], [1e-4, 2e-5, 1.0]])


@pytest.mark.parametrize("scale", [1.0, 1e-3, 1e-6, 1e-120])
def test_a_homography_at_any_scale_maps_alike(tmp_path, scale):
    np.savetxt(tmp_path / "H1to2p.txt", H * scale)
    H1 = read_homographies(tmp_path, 2)
    pts = np.array([[0.0, 0.0], [100.0, 50.0], [639.0, 479.0]])
    np.testing.assert_allclose(apply_homography(pair_homography(H1, 0, 1), pts),
                               apply_homography(H, pts), rtol=1e-9)
    np.testing.assert_allclose(apply_homography(pair_homography(H1, 1, 0),
                                                apply_homography(H, pts)), pts, atol=1e-6)


def test_a_singular_one_is_still_refused(tmp_path):
    np.savetxt(tmp_path / "H1to2p.txt", np.array([[1.0, 2, 3], [2, 4, 6], [0, 0, 1]]) * 1e-6)
    with pytest.raises(InputError, match="singular"):
        read_homographies(tmp_path, 2)
    np.savetxt(tmp_path / "H1to2p.txt", np.zeros((3, 3)))
    with pytest.raises(InputError, match="singular"):
        read_homographies(tmp_path, 2)
