"""What solving the sets at their roots costs (engines.gather.solve_at_roots), on sets small
enough to count by hand: bundles up a shortest-path tree to the root, cuts back down, ``2
ecc(root) + 1`` rounds (the counts of the module docstring)."""

import numpy as np
import pytest

from pipeline.consistency.engines.gather import solve_at_roots
from pipeline.consistency.roots import root_of
from pipeline.transport import HEADER_BYTES

# set 0: a path of five features in five cameras, 0-1-2-3-4 (conflict-free)
# set 1: 5-6-7 with 5 and 7 in camera 0 (conflictive: the merge cuts one of its two links)
SUB = np.arange(8)
CAM = np.array([0, 1, 2, 3, 4, 0, 1, 0])
COMP = np.array([0, 0, 0, 0, 0, 1, 1, 1])
A = np.array([0, 1, 2, 3, 5, 6])
B = np.array([1, 2, 3, 4, 6, 7])
Q = np.array([0.9, 0.9, 0.9, 0.9, 0.9, 0.5])


def _solve(sent=None, on=None):
    sent = np.ones(len(A), bool) if sent is None else sent
    on = np.ones(len(A), bool) if on is None else on
    return solve_at_roots(SUB, CAM, A, B, Q, on, COMP, np.zeros((len(SUB), 2)),
                          np.tile(np.eye(3, 4), (5, 1, 1)), np.array([0, 1]), sent, 5)


def test_the_roots_are_the_ends_of_both_paths():
    # the counts below take these roots: feature 0 (eccentricity 4) and 5 (eccentricity 2)
    assert root_of([0, 1, 2, 3, 4]) == 0 and root_of([5, 6, 7]) == 5


def test_the_links_come_grouped_by_set_in_ascending_sets():
    sol = _solve()
    assert sol.sets.tolist() == [0, 1]
    assert sol.set_of.tolist() == [0, 0, 0, 0, 1, 1]
    assert sol.links.tolist() == [0, 1, 2, 3, 4, 5]
    assert sol.a.tolist() == A.tolist() and sol.b.tolist() == B.tolist()
    # the conflict-free path keeps its links; the conflictive set loses its weaker one
    assert sol.cut.tolist() == [False, False, False, False, False, True]


def test_rounds_messages_and_bytes_of_two_sets_at_once():
    sol = _solve()
    assert sol.rounds == 2 * 4 + 1  # the longer set: eccentricity 4 from its root
    # bundles up: one message per hop (0+1+2+3+4 in set 0, 0+1+2 in set 1); cuts down:
    # one message per tree edge (4 + 2)
    assert sol.messages == 10 + 3 + 4 + 2
    # a bundle is 128 + 16 deg bytes: degrees 1 2 2 2 1 and 1 2 1; the one cut of set 1
    # (16 bytes) goes down its two tree edges
    up = (160 * 1 + 160 * 2 + 160 * 3 + 144 * 4) + (160 * 1 + 144 * 2)
    assert sol.nbytes == up + 16 * 2 + HEADER_BYTES * sol.messages


def test_a_cut_that_is_not_sent_back_costs_no_bytes_down():
    sent = np.ones(len(A), bool)
    sent[5] = False  # a history link: its cut is not sent back
    sol = _solve(sent=sent)
    assert sol.cut[5]
    assert sol.nbytes == _solve().nbytes - 16 * 2
    assert sol.messages == _solve().messages


@pytest.mark.parametrize("which", [0, 1])
def test_one_set_alone_costs_what_it_costs_among_others(which):
    on = COMP[np.searchsorted(SUB, A)] == which
    sol = _solve(on=on)
    assert sol.sets.tolist() == [which]
    assert sol.rounds == [9, 5][which]
    assert sol.messages == [14, 5][which]
    assert sol.nbytes == [1536, 448 + 32][which] + HEADER_BYTES * sol.messages
    # every camera of the set holds the set's bundles (the root all of them), once: camera 0
    # has two features of set 1
    bundles = [144 * 2 + 160 * 3, 144 * 2 + 160][which]
    members = np.unique(CAM[COMP == which])
    held = np.zeros(5)
    held[members] = bundles
    np.testing.assert_array_equal(sol.held, held)
