"""Every bench seed option is checked as the commands check ``--seed`` (an integer from 0 to
2**63 - 1) when the arguments are parsed: a negative seed ended in numpy's 'expected
non-negative integer' traceback, some after minutes of other cases."""

import pytest
from benchload import load_bench

#: (bench, seed option, the other arguments of a run that would otherwise start at once)
SEED_OPTIONS = [
    ("faults", "--seed", ["--formations", "1"]),
    ("consistency_scale", "--seed", ["--n", "6"]),
    ("foundation", "--seed", ["--size", "64x48"]),
    ("online", "--seed", ["--robots", "2", "--steps", "1", "--size", "64x48"]),
    ("online_cuts", "--seed", ["--robots", "2", "--steps", "1", "--size", "64x48"]),
    ("spectral_baselines", "--seed", []),
    ("team_anatomy", "--seeds", ["--n", "6"]),
    ("team_moves", "--seeds", ["--n", "6"]),
    *[("multiway", flag, ["--frames", "--graffiti", "", "--formations", "", "--warped-seeds",
                          "--team", "4"])
      for flag in ("--formation-seeds", "--warped-seeds", "--team-seeds", "--shuffle-seed",
                   "--renumber")],
    *[("sync_weights", flag, ["--frames", "--warped-seeds", "--team", "4"])
      for flag in ("--warped-seeds", "--team-seeds", "--shuffle-seed")],
]


@pytest.mark.parametrize("name, flag, args", SEED_OPTIONS)
@pytest.mark.parametrize("seed, message", [
    ("-1", "'-1': a seed must be an integer from 0 to 2**63 - 1"),
    ("x", "'x': not an integer; give a seed >= 0, e.g. 0"),
])
def test_a_seed_the_commands_refuse_is_refused_when_parsed(tmp_path, capsys, name, flag, args,
                                                           seed, message):
    out = tmp_path / "bench"
    out.mkdir()
    (out / "results.json").write_text('{"previous": true}')
    argv = [*args, flag, seed]
    if name != "spectral_baselines":  # it has no --out (--json only)
        argv += ["--out", str(out)]
    with pytest.raises(SystemExit) as exc:  # argparse's refusal: before any work
        load_bench(name).main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert f"argument {flag}: {message}" in err and "Traceback" not in err
    assert [p.name for p in out.iterdir()] == ["results.json"]
    assert (out / "results.json").read_text() == '{"previous": true}'
