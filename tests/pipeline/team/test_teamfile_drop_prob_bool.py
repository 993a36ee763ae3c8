"""A team file's option ``drop_prob: false`` (or ``true``) was taken as the probability 0 (or
refused as ``1``, out of range, naming neither): JSON's true and false are no probabilities,
and are now refused as such, as the other numeric options refuse them."""

import pytest

from pipeline.errors import InputError
from pipeline.team.teamfile import parse_team


def _doc(**options):
    return {"version": 1, "robots": [{"id": 0, "endpoint": "tcp/127.0.0.1:7000"},
                                     {"id": 1, "endpoint": "tcp/127.0.0.1:7001"}],
            "comm_edges": [[0, 1]], "options": options,
            "data": {"kind": "links", "links": "in.csv", "features_per_camera": [1, 1]}}


@pytest.mark.parametrize("value", [False, True, float("nan"), "0.1"])
def test_drop_prob_that_is_no_number_is_refused(value):
    with pytest.raises(InputError, match=r"option drop_prob .* must be in \[0, 1\)"):
        parse_team(_doc(drop_prob=value))


def test_drop_prob_numbers_are_read():
    assert parse_team(_doc(drop_prob=0)).options["drop_prob"] == 0
    assert parse_team(_doc(drop_prob=0.25)).options["drop_prob"] == 0.25
