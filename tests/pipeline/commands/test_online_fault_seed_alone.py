"""run-formation --steps with --fault-seed: the online run's own message, whatever else is given."""

import pytest

from pipeline.__main__ import main


@pytest.mark.parametrize("extra", [[], ["--switching-topology"]])
def test_fault_seed_on_an_online_run_names_the_scene_seed(extra, capsys, tmp_path):
    out = tmp_path / "run"
    argv = ["run-formation", "--steps", "2", "--fault-seed", "7", *extra,
            "--out", str(out), "--no-rerun"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "--fault-seed 7: an online run (--steps) draws the graph of each step from --seed" \
        in err
    assert "add --drop-prob" not in err  # an online run refuses --drop-prob
    assert not out.exists()
