"""bench/team_memory.py: the robots' private memory over Zenoh with the shared-memory option
off and on, side by side; a team it cannot run is refused before any work."""

import json

import pytest
from benchload import load_bench


def test_it_samples_every_robot_with_the_option_off_and_on(tmp_path, capsys):
    bench = load_bench("team_memory")
    out = tmp_path / "out"
    assert bench.main(["--robots", "3", "--size", "96x72", "--max-features", "60",
                       "--out", str(out)]) == 0
    records = json.loads((out / "results.json").read_text())["records"]
    assert [r["shared_memory"] for r in records] == [False, True]
    for r in records:
        assert r["robots"] == 3 and r["robot_processes_sampled"] == 3
        assert 0 < r["private_mb_min"] <= r["private_mb_median"] <= r["private_mb_max"]
        assert r["same_links_as_other"] is True
    assert "shared_memory off" in capsys.readouterr().out


@pytest.mark.parametrize("args, message", [
    (["--robots", "1"], "--robots 1: a team of 2 to 256 robot processes"),
    (["--robots", "300"], "--robots 300: a team of 2 to 256 robot processes"),
    (["--repeat", "0"], "argument --repeat: '0': expected a whole number of at least 1"),
])
def test_what_it_cannot_run_is_refused_first(tmp_path, capsys, args, message):
    bench = load_bench("team_memory")
    with pytest.raises(SystemExit) as exc:
        bench.main(args + ["--out", str(tmp_path / "out")])
    assert exc.value.code == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "out").exists()
