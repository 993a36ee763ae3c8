"""Benches given a count they cannot run (no repeat, no step, a cycle of one camera) refuse it
before any work with a one-line message and exit status 2, instead of a traceback or a
results.json of nothing written over the previous one."""

import inspect
from pathlib import Path

import pytest
from benchload import load_bench, previous_results, refused

ROOT = Path(__file__).resolve().parents[2]


def _bench(name):
    return load_bench(name)


@pytest.mark.parametrize("name, args, message", [
    ("foundation", ["--repeat", "0"], "argument --repeat: '0': expected a whole number of at least 1"),
    ("fusion", ["--repeat", "-1"], "argument --repeat: '-1': expected a whole number of at least 1"),
    ("team", ["--repeat", "0"], "argument --repeat: '0': expected a whole number of at least 1"),
    ("consistency_cycle", ["--repeat", "0"], "argument --repeat: '0': expected a whole number of at least 1"),
    ("consistency_cycle", ["--n", "5", "1"], "--n 1: a cycle joins at least 2 cameras"),
    ("online_team", ["--steps", "0"], "argument --steps: '0': expected a whole number of at least 1"),
    ("online_team", ["--repeat", "0"], "argument --repeat: '0': expected a whole number of at least 1"),
    ("team_bytes", ["--repeat", "0"], "argument --repeat: '0': expected a whole number of at least 1"),
    ("fusion", ["--formations", "z"], "error: unknown formation 'z'"),
    ("fusion", ["--long-rounds", "-1"], "--long-rounds -1: more than the fixed scheme's 100"),
    ("online", ["--batch-every", "-1", "--robots", "2", "--steps", "1", "--size", "64x48"],
     "--batch-every -1: expected steps >= 0"),
    ("team", ["--size", "0x0"], "--size '0x0': at least 64x48 pixels are needed"),
    ("team", ["--only", "e (6"], "--only 'e (6': no formation key holds it; the keys are 'd (6"),
    ("online_team", ["--size", "640"], "--size '640': expected WIDTHxHEIGHT, e.g. 640x480"),
    ("multiway", ["--frames", "--graffiti", "", "--formations", "", "--warped-seeds", "--team", "10",
                  "--team-methods", "sync", "foo"], "--team-methods foo: unknown; choose from"),
    ("multiway", ["--frames", "--graffiti", "", "--formations", "", "--warped-seeds", "--team", "10",
                  "--methods", "Sync"], "--methods Sync: unknown; choose from paper,"),
    ("fusion", ["--resolutions", "foo"], "error: resolution 'foo': choose one of"),
    ("voting_table1", ["--radius", "-1", "--trials", "2"], "argument --radius: '-1': expected a finite number above 0"),
    ("voting_table1", ["--trials", "1"], "--trials must be >= 2 (Table I's standard deviation"),
    ("voting_table1", ["--seed", "-1", "--trials", "2"],
     "error: --seed -1: a seed must be an integer from 0 to 2**63 - 1"),
    ("multiway", ["--frames", "--graffiti", "", "--warped-seeds", "--team", "--formations", "z"],
     "error: unknown formation 'z'"),
    ("team_moves", ["--n", "10", "1"], "--n 1: a team has at least 2 cameras"),
    ("team_profile", ["--steps", "0"], "argument --steps: '0': expected a whole number of at least 1"),
    ("team_profile", ["--top", "-1"], "argument --top: '-1': expected a whole number of at least 1"),
    ("resolution_quality", ["--seeds", "0"], "argument --seeds: '0': expected a whole number of at least 1"),
    ("resolution_quality", ["--first-seed", "-3"],
     "error: --first-seed -3: a seed must be an integer from 0 to 2**63 - 1"),
    ("resolution_quality", ["--formations", "xa"], "error: unknown formation 'x'; choose one of"),
    ("resolution_quality", ["--merge-radius", "x,2"], "--merge-radius 'x,2': expected comma"),
    ("resolution_quality", ["--merge-radius=-1,2"],
     "error: --merge-radius -1: expected pixels from 0 (merges nothing) to 480, the shorter "
     "side of the rendered images (640x480)"),
    ("resolution_quality", ["--merge-radius", "0.5,nan"], "error: --merge-radius nan: expected "),
    ("resolution_quality", ["--merge-radius", "2,inf"], "error: --merge-radius inf: expected "),
    ("resolution_quality", ["--merge-radius", "1e9"],
     "error: --merge-radius 1e+09: expected pixels from 0 (merges nothing) to 480"),
    ("multiway", ["--frames", "--graffiti", "", "--formations", "", "--warped-seeds",
                  "--team", "0"], "--team 0: a team has at least 2 cameras"),
])
def test_a_count_the_bench_cannot_run_is_refused(tmp_path, capsys, name, args, message):
    out = previous_results(tmp_path)
    assert message in refused(_bench(name).main, args + ["--out", str(out)], out, capsys)


def test_landmarks_clear_names_a_missing_data_folder_before_any_output(tmp_path, capsys):
    # it printed its table's header, then ended with an InputError traceback (its default
    # --data, ../shared/data/cmu_hotel, is not beside every clone)
    assert _bench("landmarks_clear").main(["--data", str(tmp_path / "nope"), "--quick"]) == 2
    out, err = capsys.readouterr()
    assert out == ""
    assert err == (f"error: --data {tmp_path / 'nope'}: no such folder; give the CMU hotel "
                   "folder (its frames and their label files)\n")


# images_vs_colmap's --out is a file, formations' goes to run-formations (which checks it)
FOLDER_BENCHES = sorted(p.stem for p in (ROOT / "bench").glob("*.py")
                        if 'add_argument("--out"' in p.read_text()
                        and p.stem not in ("formations", "images_vs_colmap"))


@pytest.mark.parametrize("name", FOLDER_BENCHES)
@pytest.mark.parametrize("where", ["file", "under a file"])
def test_an_out_that_cannot_be_a_folder_is_refused_before_any_work(tmp_path, capsys,
                                                                   monkeypatch, name, where):
    (tmp_path / "f").write_text("mine")
    out = tmp_path / "f" if where == "file" else tmp_path / "f" / "sub"
    monkeypatch.setattr("sys.argv", [f"{name}.py", "--out", str(out)])
    main = _bench(name).main
    with pytest.raises(SystemExit) as exc:
        main(["--out", str(out)]) if "argv" in inspect.signature(main).parameters else main()
    assert exc.value.code == 2
    err = capsys.readouterr().err
    message = "is a file; the results are written in a folder" if where == "file" else (
        f"{str(tmp_path / 'f')!r} is a file, not a folder")
    assert f"error: --out {str(out)!r}" in err and message in err and "Traceback" not in err
    assert (tmp_path / "f").read_text() == "mine"
