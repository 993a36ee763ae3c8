"""bench/team_network.py: a team, case or robot count it cannot run is refused before any
namespace is made (an unknown team was a KeyError traceback after the first team's runs)."""

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from benchload import load_bench


@pytest.mark.parametrize("args, message", [
    (["--teams", "d,foo"], "--teams foo: expected a comma list of d, ring2"),
    (["--cases", "kill,1gbit"], "--cases 1gbit: expected a comma list of unlimited, "),
    (["--cases", ","], "--cases ',': expected a comma list of"),
    (["--robots", "1"], "--robots 1: a team has at least 2 robots"),
    (["--size", "big"], "--size 'big': expected WIDTHxHEIGHT, e.g. 640x480"),
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


CHILD = """
import sys, time
sys.path.insert(0, {tests!r})
from pathlib import Path
from benchload import load_bench
bench = load_bench("team_network")
marks = Path({marks!r})

class Rig:  # stands for NetnsRig: no namespace is made
    def __init__(self, n, edges):
        pass
    def __enter__(self):
        (marks / "made").write_text("")
        return self
    def __exit__(self, *exc):
        (marks / "removed").write_text("")
    def team(self, *a, **k):
        time.sleep(60)

bench.unavailable = lambda: None
bench.NetnsRig = Rig
bench.main(["--teams", "d", "--cases", "unlimited", "--out", str(marks / "out")])
"""


def test_a_sigterm_removes_the_namespaces_as_ctrl_c_does(tmp_path):
    """timeout and kill send SIGTERM: the rig's namespaces were left behind (fmPIDxK-*)."""
    tests = str(Path(__file__).resolve().parent)
    proc = subprocess.Popen([sys.executable, "-c", CHILD.format(tests=tests, marks=str(tmp_path))])
    try:
        for _ in range(600):
            if (tmp_path / "made").exists() or proc.poll() is not None:
                break
            time.sleep(0.1)
        assert (tmp_path / "made").exists()
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=60) == 128 + signal.SIGTERM
    finally:
        proc.kill()
    assert (tmp_path / "removed").exists()


def _row(case, wall, lost, need=None, outcomes=("done", "done")):
    return {"case": case, "wall_s": wall, "rounds": 7, "links": 10,
            "outcomes": {str(i): o for i, o in enumerate(outcomes)},
            "conflictive_sets_after": 0, "links_lost": lost,
            "links_decided_differently": 0 if lost is not None else None,
            "bytes_counted": 2_000_000, "bytes_packets": 1_500_000, "bytes_socket": 1_600_000,
            "bytes_alone_need_s": need,
            "per_link": {"0-1": {"socket": 1_000_000}, "1-2": {"socket": 600_000}}}


def test_the_table_is_printed_from_the_saved_results(tmp_path, capsys):
    """The README's table comes from the bench: at the end of a run, and again from a saved
    results.json with --reprint (nothing run)."""
    import json

    bench = load_bench("team_network")
    saved = {"teams": {"ring2": {"robots": 3, "rows": [
        _row("unlimited", 1.234, 0), _row("1mbit", 2.5, 0, need=0.456),
        _row("kill", 1.0, 4, outcomes=("cut", "done", "cut"))]}}}
    path = tmp_path / "results.json"
    path.write_text(json.dumps(saved))
    assert bench.main(["--reprint", str(path)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[2] == ("| ring2, 3 | unlimited | 1.23 s | 7 | done 2 | 0 | 0 of 10 | 0 | "
                        "2.00 / 1.50 / 1.60 | 1.00 MB | – |")
    assert lines[3].endswith("| 0.46 s |")
    assert "| cut 2, done 1 | 0 | 4 of 10 |" in lines[4]
    assert len(lines) == 5


def test_a_reprint_of_another_file_is_refused(tmp_path, capsys):
    bench = load_bench("team_network")
    path = tmp_path / "results.json"
    path.write_text('{"size": [640, 480]}')
    with pytest.raises(SystemExit) as exc:
        bench.main(["--reprint", str(path)])
    assert exc.value.code == 2
    assert "not this bench's results.json" in capsys.readouterr().err
