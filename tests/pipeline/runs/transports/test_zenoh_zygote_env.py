"""FORMATION_MATCH_ZYGOTE (pipeline.runs.transports.zenoh.ZYGOTE_ENV): an online run's teams
share one zygote by default (``run``) or each have their own (``team``); any other value is
refused by name before a team starts."""

import pytest

from pipeline.errors import InputError
from pipeline.runs.transports import zenoh
from pipeline.team import launcher


@pytest.mark.parametrize(("value", "shared"), [(None, True), ("run", True), ("", True),
                                               ("team", False)])
def test_the_online_robots_block_shares_a_zygote_unless_told(value, shared, monkeypatch):
    if value is None:
        monkeypatch.delenv(zenoh.ZYGOTE_ENV, raising=False)
    else:
        monkeypatch.setenv(zenoh.ZYGOTE_ENV, value)
    with zenoh.online_robots():
        inside = launcher._within["zygote"]
    assert (inside is not None) is shared
    assert launcher._within["zygote"] is None


def test_another_value_is_refused_by_name(monkeypatch):
    monkeypatch.setenv(zenoh.ZYGOTE_ENV, "shared")
    with pytest.raises(InputError, match=r"FORMATION_MATCH_ZYGOTE='shared': choose one of run, team"):
        with zenoh.online_robots():
            pass
