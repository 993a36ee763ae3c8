"""Fuzzed team files (``robot --team``, ``observe``): every damaged TEAM.json is read to a team
or refused with an InputError naming the file."""

import json
import sys
import tempfile
from pathlib import Path

from hypothesis import given
from hypothesis import strategies as st

from pipeline.team.teamfile import load_team

sys.path.insert(0, str(Path(__file__).parents[1]))
from mutants import FUZZ, bytes_mutant, json_mutant, read_or_refuse  # noqa: E402

_ROBOTS = [{"id": i, "endpoint": f"tcp/127.0.0.1:{7000 + i}"} for i in range(3)]
_CAM = {"K": [[100.0, 0, 50], [0, 100.0, 40], [0, 0, 1]], "R": [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
        "t": [0.0, 0.0, 1.5]}
_BASE = {"version": 1, "name": "t", "robots": _ROBOTS, "comm_edges": [[0, 1], [1, 2]],
         "observer": {"endpoint": "tcp/127.0.0.1:7400"},
         "options": {"drop_prob": 0.1, "round_timeout_s": 5.0, "merge_radius": 2.0,
                     "max_features": 500, "wire": "plain"},
         "robot_options": {"2": {"loss_timeout": 9}}}
VALID = [
    {**_BASE, "data": {"kind": "links", "links": ["a.csv", "b.csv", "c.csv"],
                       "features_per_camera": [2, 2, 2], "keypoints": ["k0", "k1", "k2"],
                       "cameras": [_CAM, {"P": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 1]]}, None],
                       "weights": ["w0", "w1", "w2"], "history": ["h0", "h1", "h2"]}},
    {**_BASE, "data": {"kind": "formation", "formation": "d", "seed": 0, "size": [640, 480],
                       "robots": 3, "graph": None}},
    {**_BASE, "data": {"kind": "images", "images": ["a.jpg", "b.jpg", "c.jpg"],
                       "intrinsics": [_CAM["K"], None, _CAM["K"]],
                       "intrinsics_known": [True, False, True], "max_size": 1600,
                       "intrinsics_source": ["K.txt", "guess", "K.txt"]}},
    {**_BASE, "data": {"kind": "online-match", "step": 2, "window": 3,
                       "frames": ["f0.npz", "f1.npz", "f2.npz"], "store": ["r0", "r1", "r2"]}},
]


def _load(text: bytes):
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "TEAM.json"
        path.write_bytes(text)
        team = read_or_refuse(lambda: load_team(path), str(path))
        if team is not None:
            assert team.n >= 2 and len(team.robots) == team.n
            for i in range(team.n):
                team.options_for(i)
                team.neighbours(i)


@FUZZ
@given(st.sampled_from(VALID).flatmap(json_mutant))
def test_a_team_file_with_wrong_values_is_read_or_refused(doc):
    _load(json.dumps(doc).encode())


@FUZZ
@given(st.sampled_from(VALID).flatmap(lambda d: bytes_mutant(json.dumps(d).encode())))
def test_a_damaged_team_file_is_read_or_refused(text):
    _load(text)
