"""A long delay with message loss does not make live robots look crashed: the loss timeout
grew by ``2 D`` with the delay ``D`` while a dropped message's retransmission is answered
``4 (D + 1)`` rounds after the first sending, so from ``D = 19`` one drop made a neighbour
look lost (``run-formation --drop-prob 0.1 --delay-rounds 40`` cut every link of formation d
as ``robot-lost``)."""

import json

import pytest

from pipeline.__main__ import main
from pipeline.consistency.protocols import ProtocolOptions


@pytest.mark.parametrize("seed", [0, 1])
def test_robots_under_delay_and_loss_lose_no_live_neighbour(tmp_path, capsys, seed):
    links = tmp_path / "links.csv"
    # a triangle of cameras whose chain 0:0 - 1:0 - 2:0 - 0:1 - 1:1 joins two features of
    # cameras 0 and 1: a conflictive set to resolve
    links.write_text("0,0,1,0\n1,0,2,0\n2,0,0,1\n0,1,1,1\n")
    report = tmp_path / "report.json"
    assert main(["resolve", "-q", "--links", str(links), "--out", str(tmp_path / "out.csv"),
                 "--report", str(report), "--resolution", "paper", "--drop-prob", "0.3",
                 "--delay-rounds", "40", "--fault-seed", str(seed)]) == 0
    summary = json.loads(report.read_text())
    assert summary["faults"]["robots_lost"] == {}
    assert summary["faults"]["links_cut_robot_lost"] == 0
    assert summary["after"]["conflictive_sets"] == 0 and summary["deleted"] >= 1
    assert "declared lost" not in capsys.readouterr().err


def test_the_loss_timeout_leaves_a_dropped_message_its_tries_under_delay():
    base = ProtocolOptions()
    for d in (0, 1, 19, 40, 100):
        opts = ProtocolOptions.for_delay(d)
        # the tries within T silent rounds: the first sending, then one a round from
        # retransmit_after on, each answered a round trip 2 (D + 1) later
        tries = opts.loss_timeout - opts.retransmit_after - 2 * (d + 1) + 2
        assert tries == base.loss_timeout - 2, d
