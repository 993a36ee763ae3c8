"""bench/team_network.py: a team, case or robot count it cannot run is refused before any
namespace is made (an unknown team was a KeyError traceback after the first team's runs)."""

import pytest
from benchload import load_bench


@pytest.mark.parametrize("args, message", [
    (["--teams", "d,foo"], "--teams foo: expected a comma list of d, ring2"),
    (["--cases", "kill,1gbit"], "--cases 1gbit: expected a comma list of unlimited, "),
    (["--cases", ","], "--cases ',': expected a comma list of"),
    (["--robots", "1"], "--robots 1: a team has at least 2 robots"),
])
def test_what_it_cannot_run_is_refused_first(tmp_path, capsys, monkeypatch, args, message):
    bench = load_bench("team_network")
    # never a real rig here: without the check, the bench would stop at this line instead
    monkeypatch.setattr(bench, "unavailable", lambda: "no rig in the tests")
    with pytest.raises(SystemExit) as exc:
        bench.main(args + ["--out", str(tmp_path)])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert list(tmp_path.iterdir()) == []
