"""The benches that time ``run-formation`` (run_formation, online_team, team_profile) check
--formation before starting it: an unknown one was refused by the command they started, then
ended the bench with exit 1 (online_team: a RuntimeError traceback)."""

import sys

import pytest
from benchload import load_bench


@pytest.mark.parametrize("name", ["run_formation", "online_team", "team_profile"])
def test_an_unknown_formation_is_refused_before_any_run(tmp_path, capsys, monkeypatch, name):
    out = tmp_path / "bench"
    out.mkdir()
    (out / "results.json").write_text('{"previous": true}')
    argv = ["--formation", "z", "--out", str(out)]
    bench = load_bench(name)
    try:
        if name == "run_formation":  # its main reads sys.argv
            monkeypatch.setattr(sys, "argv", [f"bench/{name}.py", *argv])
            code = bench.main()
        else:
            code = bench.main(argv)
    except SystemExit as exc:
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err
    assert err.strip() == ("error: unknown formation 'z'; choose one of a, b, c, d (the paper's "
                           "Fig. 4) or a graph kind (line, ring, ring2, complete, geometric)")
    assert (out / "results.json").read_text() == '{"previous": true}'
