"""ProtocolOptions given by a user's code: timers that are not a number of rounds are named."""

import pytest

from pipeline.consistency import ProtocolOptions, resolve_conflicts
from pipeline.errors import InputError
from pipeline.types import Links


@pytest.mark.parametrize("name, value", [("loss_timeout", 0), ("loss_timeout", -3),
                                         ("retransmit_after", 0), ("heartbeat_every", 2.5)])
def test_timers_below_one_round_are_refused_naming_them(name, value):
    # loss_timeout 0 declared every neighbour lost at once: every link of Fig. 1 was cut
    links = Links([0, 1, 2, 0], [0, 0, 0, 1], [1, 2, 3, 3], [0, 0, 0, 0])
    with pytest.raises(InputError, match=f"ProtocolOptions {name} {value}: give a whole "
                                         "number of rounds >= 1"):
        resolve_conflicts([2, 1, 1, 1], None, links,
                          protocol=ProtocolOptions(reliable=True, **{name: value}))


def test_the_defaults_and_the_delay_timers_are_accepted():
    assert ProtocolOptions.for_delay(3).loss_timeout == ProtocolOptions().loss_timeout + 12


@pytest.mark.parametrize("field", ["reliable", "delta_messages"])
def test_protocol_switches_are_booleans_or_none(field):
    """reliable='no' (or delta_messages='no') was read as True."""
    with pytest.raises(InputError, match=rf"ProtocolOptions {field} 'no': give True, False or "
                                         r"None"):
        ProtocolOptions(**{field: "no"})
    with pytest.raises(InputError, match=rf"ProtocolOptions {field} 0"):
        ProtocolOptions(**{field: 0})
    assert ProtocolOptions(**{field: False}) != ProtocolOptions(**{field: True})
