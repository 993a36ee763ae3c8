"""A hand-written links team whose robots' own files disagree on a link they share: both ends
of a link compare their rows in the first round (pipeline.team.robot.check_shared_links) and
stop with one line naming the link, the two values and what to do, where a ``sync`` team ran
out of Borůvka rounds with a traceback and the other rules decided on one end's value."""

import json
import re
import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest

from pipeline.errors import InputError
from pipeline.team.robot import SHARED_LINKS, check_shared_links

HEADER = "cam_i,feat_i,cam_j,feat_j,quality\n"


def _team(tmp_path, files: dict, edges, fpc, resolution="sync", weights=None) -> list:
    """Write the robots' links (and weights) files and TEAM.json in ``tmp_path``; start one
    ``robot`` command per robot and return ``(exit code, stderr)`` of each."""
    from pipeline.team.launcher import free_ports

    for name, text in files.items():
        (tmp_path / name).write_text(text)
    n = len(fpc)
    data = {"kind": "links", "links": [f"r{i}.csv" for i in range(n)],
            "features_per_camera": fpc}
    if weights is not None:
        for i, rows in enumerate(weights):
            (tmp_path / f"w{i}.csv").write_text("weight\n" + "".join(f"{w}\n" for w in rows))
        data["weights"] = [f"w{i}.csv" for i in range(n)]
    doc = {"version": 1, "name": "hand", "comm_edges": edges,
           "robots": [{"id": i, "endpoint": f"tcp/127.0.0.1:{p}"}
                      for i, p in enumerate(free_ports(n))],
           "data": data, "options": {"resolution": resolution, "start_timeout_s": 20.0,
                                     "round_timeout_s": 5.0}}
    (tmp_path / "TEAM.json").write_text(json.dumps(doc))
    procs = [subprocess.Popen([sys.executable, "-m", "pipeline", "robot", "--team", "TEAM.json",
                               "--id", str(i)], cwd=tmp_path, stdout=subprocess.DEVNULL,
                              stderr=subprocess.PIPE, text=True) for i in range(n)]
    out = []
    for p in procs:
        try:
            _, err = p.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            p.kill()
            _, err = p.communicate()
        out.append((p.returncode, err))
    return out


def _error_line(err: str) -> str:
    """The robot's one ``error:`` line; no traceback beside it."""
    assert "Traceback" not in err, err
    (line,) = [ln for ln in err.splitlines() if ln.startswith("error:")]
    return line


def test_two_ends_that_give_a_link_different_qualities_stop_with_one_line(tmp_path):
    """Three robots, each with its own links file; robots 0 and 1 give their link qualities
    0.9 and 0.8. sync ran out of Borůvka rounds (a traceback, exit 1); now both ends exit 2
    naming the link and both qualities, and robot 2 ends on the links it has left."""
    files = {"r0.csv": HEADER + "0,0,1,0,0.9\n0,0,2,0,0.5\n",
             "r1.csv": HEADER + "0,0,1,0,0.8\n1,0,2,1,0.7\n",
             "r2.csv": HEADER + "0,0,2,0,0.5\n1,0,2,1,0.7\n"}
    (c0, e0), (c1, e1), (c2, e2) = _team(tmp_path, files, [[0, 1], [1, 2], [0, 2]], [1, 1, 2])
    assert (c0, c1) == (2, 2), (e0, e1)
    assert _error_line(e0) == (
        "error: robot 0: link (0,0)-(1,0) has quality 0.9 in its links file r0.csv but 0.8 in "
        "robot 1's (data.links[1]); give both ends the same quality")
    assert _error_line(e1) == (
        "error: robot 1: link (1,0)-(0,0) has quality 0.8 in its links file r1.csv but 0.9 in "
        "robot 0's (data.links[0]); give both ends the same quality")
    assert "Traceback" not in e2 and c2 == 0, e2


def test_two_ends_that_give_a_link_different_weights_stop_with_one_line(tmp_path):
    """data.weights: robot 0's weights file gives link (0,0)-(1,0) 4.0, robot 1's 3.5 (the
    quality columns agree and are not read)."""
    files = {"r0.csv": HEADER + "0,0,1,0,0.9\n", "r1.csv": HEADER + "0,0,1,0,0.9\n"}
    (c0, e0), (c1, e1) = _team(tmp_path, files, [[0, 1]], [1, 1], weights=[[4.0], [3.5]])
    assert (c0, c1) == (2, 2), (e0, e1)
    assert _error_line(e0) == (
        "error: robot 0: link (0,0)-(1,0) has weight 4.0 in its weights file w0.csv but 3.5 in "
        "robot 1's (data.weights[1]); give both ends the same weight")
    assert re.fullmatch(r"error: robot 1: link \(1,0\)-\(0,0\) has weight 3\.5 .* but 4\.0 in "
                        r"robot 0's \(data\.weights\[0\]\); give both ends the same weight",
                        _error_line(e1))


def test_a_link_in_one_ends_file_only_is_named(tmp_path):
    """Robot 1's file leaves out the link robot 0 lists (sync ran out of rounds on it too,
    and paper decided on robot 0's side alone)."""
    files = {"r0.csv": HEADER + "0,0,1,0,0.9\n0,1,1,1,0.9\n", "r1.csv": HEADER + "0,1,1,1,0.9\n"}
    (c0, e0), (c1, e1) = _team(tmp_path, files, [[0, 1]], [2, 2], resolution="paper")
    assert (c0, c1) == (2, 2), (e0, e1)
    assert _error_line(e0) == (
        "error: robot 0: link (0,0)-(1,0) is in its links file r0.csv but not in robot 1's "
        "(data.links[1]); both ends of a link list it: give both files every link the two "
        "robots share")
    assert _error_line(e1) == (
        "error: robot 1: link (1,0)-(0,0) is in robot 0's links file (data.links[0]) but not in "
        "its links file r1.csv; both ends of a link list it: give both files every link the two "
        "robots share")


def _msg(src, r, s, value=None):
    payload = {"r": np.asarray(r, np.int32), "s": np.asarray(s, np.int32)}
    if value is not None:
        payload["value"] = np.asarray(value, np.float64)
    return SimpleNamespace(src=src, kind=SHARED_LINKS, payload=payload)


WHERE = {"own": "its links file r0.csv", "own_values": "its links file r0.csv",
         "links": "data.links", "values": "data.links"}


def test_the_comparison_matches_rows_in_any_order_and_ignores_values_it_is_not_given():
    nbr, r, s = np.array([1, 1, 2]), np.array([0, 3, 1]), np.array([5, 2, 0])
    q = np.array([0.9, np.inf, 0.5])
    # robot 1 lists the same two links in another order, robot 2 its one: all agree
    inbox = [_msg(2, [0], [1], [0.5]), _msg(1, [2, 5], [3, 0], [np.inf, 0.9])]
    check_shared_links(0, inbox, nbr, r, s, q, "quality", WHERE)
    # a rule that does not weigh links compares the rows only
    check_shared_links(0, [_msg(1, [2, 5], [3, 0])], nbr, r, s, None, "quality", WHERE)
    bad = [_msg(1, [2, 5], [3, 0], [np.inf, 0.8])]
    check_shared_links(0, bad, nbr, r, s, None, "quality", WHERE)
    with pytest.raises(InputError, match=r"^robot 0: link \(0,0\)-\(1,5\) has quality 0\.9 in "
                                         r"its links file r0\.csv but 0\.8 in robot 1's"):
        check_shared_links(0, bad, nbr, r, s, q, "quality", WHERE)


def test_a_neighbour_that_lists_no_link_or_an_extra_one_is_named():
    nbr, r, s = np.array([1]), np.array([0]), np.array([5])
    with pytest.raises(InputError, match=r"link \(0,0\)-\(1,5\) is in its links file r0\.csv "
                                         r"but not in robot 1's \(data\.links\[1\]\)"):
        check_shared_links(0, [_msg(1, [], [])], nbr, r, s, None, "quality", WHERE)
    with pytest.raises(InputError, match=r"link \(0,7\)-\(2,4\) is in robot 2's links file "
                                         r"\(data\.links\[2\]\) but not in its links file"):
        check_shared_links(0, [_msg(2, [4], [7])], nbr, r, s, None, "quality", WHERE)
