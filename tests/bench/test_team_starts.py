"""bench/team_starts.py: consecutive teams forked each from its own zygote and all from one,
side by side, with the same cuts; what it cannot run is refused before any work."""

import json

import pytest
from benchload import load_bench


def test_it_times_both_sides_and_every_team_cuts_alike(tmp_path, capsys):
    bench = load_bench("team_starts")
    out = tmp_path / "out"
    assert bench.main(["--robots", "3", "--teams", "2", "--repeat", "1", "--out", str(out)]) == 0
    res = json.loads((out / "results.json").read_text())
    assert set(res["seconds_per_team"]) == {"a zygote per team", "one zygote for all"}
    assert all(len(v) == 1 and v[0] > 0 for v in res["seconds_per_team"].values())
    assert res["same_cuts"] is True
    assert "one zygote / a zygote per team" in capsys.readouterr().out


def test_the_ring_holds_one_conflictive_set():
    from pipeline.consistency.centralized import union_find_conflicts
    from pipeline.inputs.linkscsv import read_links_csv

    bench = load_bench("team_starts")
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as tmp:
        path, fpc, edges = bench.ring_links(Path(tmp), 5)
        links = read_links_csv(path).links
    _, conflictive = union_find_conflicts(fpc, links)
    # the ring's feature 0s and camera 0's feature 1: one set, holding camera 0 twice
    assert int(conflictive.sum()) == 6 and len(edges) == 5


@pytest.mark.parametrize("args, message", [
    (["--robots", "2"], "--robots: '2': give a whole number of robots from 3 to 16"),
    (["--robots", "100"], "--robots: '100': give a whole number of robots from 3 to 16"),
    (["--teams", "0"], "argument --teams: '0': expected a whole number of at least 1"),
])
def test_what_it_cannot_run_is_refused_first(tmp_path, capsys, args, message):
    bench = load_bench("team_starts")
    with pytest.raises(SystemExit) as exc:
        bench.main(args + ["--out", str(tmp_path / "out")])
    assert exc.value.code == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "out").exists()
