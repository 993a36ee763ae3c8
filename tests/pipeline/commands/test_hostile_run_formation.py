"""run-formation (and its run folder), as a hostile user would run it: a bad --out or a
meaningless value is refused at once with one line on stderr and exit 2, nothing touched."""

import json
import sys
from pathlib import Path

import pytest

from pipeline.__main__ import main

sys.path.insert(0, str(Path(__file__).parent))
from hostile import one_line_error, refused, run_capped, tree  # noqa: E402

FAST = ["--size", "256x192", "--max-features", "200", "--no-rerun", "--no-fusion"]




@pytest.fixture
def checkout(tmp_path, monkeypatch):
    """A folder that looks like a user's checkout, made the current folder."""
    (tmp_path / ".git").mkdir()
    (tmp_path / ".git" / "HEAD").write_text("ref: refs/heads/main\n")
    (tmp_path / "notes.txt").write_text("mine")
    (tmp_path / "sub").mkdir()
    monkeypatch.chdir(tmp_path / "sub")
    return tmp_path


@pytest.mark.parametrize("out", [".", "..", "/", "CWD", "PARENT"])
def test_out_naming_the_cwd_a_parent_or_root_is_refused(checkout, capsys, out):
    before = tree(checkout)
    out = {"CWD": str(checkout / "sub"), "PARENT": str(checkout)}.get(out, out)
    assert main(["run-formation", "--out", out, *FAST]) == 2
    one_line_error(capsys, "replaced as a whole")
    assert tree(checkout) == before


@pytest.mark.parametrize("extra", [[], ["--steps", "2"]])
def test_an_empty_out_is_refused_not_the_default_run_folder(checkout, capsys, extra):
    """--out '' (an unset variable) ran into the default runs/formation-d, replacing the
    run there."""
    assert main(["run-formation", *FAST, *extra, "--out", ""]) == 2
    one_line_error(capsys, "--out '' is empty (an unset variable?)")
    assert not (checkout / "runs").exists()


def test_out_naming_a_foreign_folder_is_refused(checkout, capsys):
    before = tree(checkout)
    assert main(["run-formation", "--out", str(checkout), *FAST]) == 2
    assert main(["run-formation", "--out", str(checkout / ".git"), *FAST]) == 2
    err = capsys.readouterr().err
    assert "not a formation-match run folder" in err and "Traceback" not in err
    assert tree(checkout) == before


def test_out_naming_a_file_or_a_symlink_is_refused(checkout, capsys):
    (checkout / "link").symlink_to(checkout / ".git")
    assert main(["run-formation", "--out", str(checkout / "notes.txt"), *FAST]) == 2
    one_line_error(capsys, "is a file")
    assert main(["run-formation", "--out", str(checkout / "link"), *FAST]) == 2
    one_line_error(capsys, "symbolic link")
    assert (checkout / "notes.txt").read_text() == "mine"


@pytest.mark.parametrize("flag,value,message", [
    ("--tol-px", "-1", "--tol-px -1.0"),
    ("--tol-px", "nan", "--tol-px nan"),
    ("--tol-px", "0", "> 0"),
    ("--size", "100000x100000", "too large"),
    ("--size", "8192x8192", "too large"),
    ("--fault-seed", "-5", "--fault-seed -5"),
    ("--seed", "-5", "--seed -5"),
    ("--drop-prob", "-0.1", "--drop-prob"),
    ("--crash", "x@1", "--crash"),
    ("--delay-rounds", "-2", "--delay-rounds -2"),
    ("--delay-rounds", "1e3", "not a whole number"),
    ("--max-features", "99999999999999999999", "at most 1000000"),
    ("--formation", "e", "unknown formation 'e'"),
    ("--window", "2", "--window applies to an online job only; add --steps N"),
    ("--hold", "0", "--hold applies to an online job only"),
    ("--batch-every", "1", "--batch-every applies to an online job only"),
    ("--speed", "0.3", "--speed applies to an online job only; add --steps N"),
    # a robot that does not exist: refused before the render (it was after the matching)
    ("--crash", "9@1", "--crash 9@1: robot 9 does not exist"),
])
def test_meaningless_values_are_refused_before_any_work(tmp_path, capsys, flag, value, message):
    out = tmp_path / "run"
    assert main(["run-formation", "--out", str(out), *FAST, flag, value]) == 2
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1 and message in lines[0] and "Traceback" not in err, err
    assert "[render]" not in err  # not even the first stage opened
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_huge_size_is_refused_under_a_small_memory_cap(tmp_path):
    proc = run_capped(["run-formation", "--size", "100000x100000", "--out", tmp_path / "r"])
    assert proc.returncode == 2 and "too large" in proc.stderr
    assert "Traceback" not in proc.stderr


def test_result_left_with_conflicts_exits_3_and_is_flagged(tmp_path, capsys):
    out = tmp_path / "run"
    crashes = [a for k in range(1, 6) for a in ("--crash", f"{k}@{k}")]
    code = main(["run-formation", "--formation", "d", "--out", str(out), *FAST, *crashes])
    report = json.loads((out / "report.json").read_text())
    assert report["after"]["conflictive_sets"] > 0  # the case this test is about
    assert code == 3 and report["conflict_free"] is False
    assert "error: the result is not conflict-free" in capsys.readouterr().err
    # and the folder carries the marker: the next run may replace it
    assert (out / ".formation-match-run").is_file()


def test_ctrl_c_is_one_line_exit_130_and_nothing_written(tmp_path, capsys, monkeypatch):
    import pipeline.stages as run

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(run, "extract_and_match", interrupted)
    out = tmp_path / "run"
    assert main(["run-formation", "--formation", "a", "--out", str(out), *FAST]) == 130
    err = capsys.readouterr().err
    assert err.splitlines()[-1].startswith("interrupted:") and "Traceback" not in err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("argv,needle", [
    (["--robots", "100000", "--graph", "ring"], "--robots 100000: give a number of robots "
                                                "from 2 to 1000"),
    (["--robots", "lots", "--graph", "ring"], "--robots 'lots': not a whole number"),
    (["--robots", "500", "--graph", "ring"], "500 robots at 640x480 would need about 13.8 GB"),
    (["--size", "4096x4096"], "6 robots at 4096x4096"),
    (["--robots", "20", "--graph", "ring", "--max-memory-gb", "nan"], "--max-memory-gb 'nan'"),
], ids=["robots-100000", "robots-text", "robots-500", "size-4096", "limit-nan"])
def test_a_formation_too_large_for_memory_is_refused_before_rendering(tmp_path, capsys,
                                                                      monkeypatch, argv,
                                                                      needle):
    """--robots 100000 ran to 3.3 GB and out of memory: the robots' views are counted
    first."""
    import pipeline.runs.formation as run

    monkeypatch.setattr(run, "run_formation", lambda *a, **k: pytest.fail("it rendered"))
    assert main(["run-formation", "--out", str(tmp_path / "run"), *argv]) == 2
    one_line_error(capsys, needle)
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("speed", ["inf", "-inf", "nan", "-0.5", "1e308"])
def test_online_speed_that_is_no_distance_is_named_as_the_option(tmp_path, capsys, speed):
    out = tmp_path / "run"
    assert main(["run-formation", "--out", str(out), *FAST, "--steps", "2",
                 f"--speed={speed}"]) == 2
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1 and f"--speed {float(speed)}" in lines[0], err
    assert "[render]" not in err
    assert not out.exists()


@pytest.mark.parametrize(("argv", "named"), [
    (["--drop-prob", "0.1"], "--drop-prob 0.1: "),
    (["--delay-rounds", "2", "--switching-topology"], "--delay-rounds 2: "),
    (["--crash", "1@3", "--crash", "2@4"], "--crash 1@3, --crash 2@4: "),
])
def test_online_fault_flags_are_refused_by_name(tmp_path, capsys, argv, named):
    """An online run refused every fault flag but --switching-topology without saying which
    one it was given ('drop the other fault options')."""
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "mine.txt").write_text("kept")
    refused(capsys, ["run-formation", "--out", str(tmp_path / "run"), *FAST, "--steps", "2",
                     *argv], tmp_path, named, "--switching-topology")
