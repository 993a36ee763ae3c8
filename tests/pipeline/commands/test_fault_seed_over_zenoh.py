"""--fault-seed without drops over robot processes: the advice names only what they model."""

import pytest

from pipeline.__main__ import main


@pytest.mark.parametrize("command", ["resolve", "run-formation"])
def test_fault_seed_alone_over_zenoh_advises_only_drops(command, capsys, tmp_path):
    links = tmp_path / "l.csv"
    links.write_text("0,0,1,0\n")
    out = tmp_path / "out"
    args = (["resolve", "--links", str(links), "--out", str(out)] if command == "resolve"
            else ["run-formation", "--out", str(out), "--no-rerun"])
    assert main([*args, "--transport", "zenoh", "--fault-seed", "7"]) == 2
    err = capsys.readouterr().err
    assert "--fault-seed 7: it seeds the message drops" in err
    assert "add --drop-prob, or drop --fault-seed" in err
    assert "--switching-topology" not in err  # refused over zenoh
    assert not out.exists()
