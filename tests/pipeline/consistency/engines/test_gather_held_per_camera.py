"""``RootSolution.held`` is the bundle bytes each camera holds (engines.gather): a camera with
two features in one set holds that set's bundles once, not once per feature; a camera in two
sets holds both sets' bundles."""

import numpy as np

from pipeline.consistency.engines.gather import solve_at_roots

P = np.tile(np.eye(3, 4), (3, 1, 1))


def _held(sub, cam, comp, a, b):
    q = np.full(len(a), 0.2)
    return solve_at_roots(np.asarray(sub), np.asarray(cam), np.asarray(a), np.asarray(b), q,
                          np.ones(len(a), bool), np.asarray(comp), np.zeros((len(sub), 2)), P,
                          np.unique(comp), np.ones(len(a), bool), 3).held


def test_a_camera_with_two_features_of_one_set_holds_the_set_once():
    # features 10 and 11 of camera 0 both linked to feature 20 of camera 1: one set of
    # bundles 128 + 16 deg = 144 + 144 + 160 bytes
    held = _held([10, 11, 20], [0, 0, 1], [0, 0, 0], [10, 11], [20, 20])
    np.testing.assert_array_equal(held, [448, 448, 0])


def test_a_camera_in_two_sets_holds_both():
    # set 0: 10 (camera 0) - 20 (camera 1) - 11 (camera 0); set 1: 12 (camera 0) - 30 (camera 2)
    held = _held([10, 11, 12, 20, 30], [0, 0, 0, 1, 2], [0, 0, 1, 0, 1],
                 [10, 11, 12], [20, 20, 30])
    np.testing.assert_array_equal(held, [448 + 288, 448, 288])
