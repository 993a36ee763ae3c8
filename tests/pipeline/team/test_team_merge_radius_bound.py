"""A team file of a rendered formation took option merge_radius 1e9 (or any radius wider than
data.size): every robot merged its image's keypoints across the whole image; it is refused
like run-formation's --merge-radius, naming the value and 0 to the shorter side."""

import re

import pytest

from pipeline.errors import InputError
from pipeline.team.teamfile import parse_team


def _doc(options=None, robot_options=None):
    return {"version": 1, "name": "t", "comm_edges": [[i, (i + 1) % 6] for i in range(6)],
            "robots": [{"id": i, "endpoint": f"tcp/127.0.0.1:{17300 + i}"} for i in range(6)],
            "data": {"kind": "formation", "formation": "d", "seed": 0, "size": [96, 72]},
            "options": options or {}, "robot_options": robot_options or {}}


@pytest.mark.parametrize("doc, where", [
    (_doc({"merge_radius": 1e9}), "options merge_radius 1000000000.0"),
    (_doc(robot_options={"2": {"merge_radius": 73}}), "robot_options['2'] merge_radius 73"),
])
def test_a_radius_wider_than_the_images_is_refused(doc, where):
    with pytest.raises(InputError, match=re.escape(where) + r" must be pixels from 0 to 72, the shorter "
                                         r"side of data.size 96x72"):
        parse_team(doc)


def test_the_shorter_side_itself_is_taken():
    assert parse_team(_doc({"merge_radius": 72})).options_for(0)["merge_radius"] == 72
