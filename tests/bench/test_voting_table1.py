"""bench/voting_table1.py: the Monte Carlo of Table I runs the paper's fixed-round scheme, and
picks each robot's winning hypothesis by the plain argmax of its votes, as the pipeline's
fixed-round fusion does (``tie_tol=0``). The votes of 100 rounds on a graph redrawn every
round have not converged, so two close votes are not a tie of counts; the Monte Carlo took
the tie rule of the converged modes (votes within 1e-4 tied, lowest index wins), which moved
its figures away from those its docstring reports."""

import json

import pytest
from benchload import load_bench

from pipeline.fusion.consensus import RandomGeometricTopology, ransac_hypotheses
from pipeline.fusion.voting import dynamic_voting, static_voting

TRIALS = 10  # seed 0: the tie rule and the argmax pick different winners on these
METHODS = {"static": (static_voting, (100, 100, 100), 300), "dynamic": (dynamic_voting, 100, 100)}


def _vote(bench, x, cov, method, gate, p, tie_tol):
    vote, rounds, _ = METHODS[method]
    return vote(x, cov, RandomGeometricTopology(20, TRIALS, radius=0.4, seed=1),
                K=ransac_hypotheses(bench.P_IN, bench.C, bench.SUCCESS), c=bench.C, p=p,
                gate=gate, rounds=rounds, rng=2, tie_tol=tie_tol)


@pytest.mark.parametrize("eig", ["truncated", "folded"])
def test_the_monte_carlo_picks_winners_by_the_plain_argmax(eig):
    bench = load_bench("voting_table1")
    rows = bench.run_reading_family(TRIALS, "literal", eig, 0, 0.4, lambda msg: None)
    x, cov, outlier = bench.monte_carlo_data(TRIALS, "literal", eig, 0)
    moved = 0
    for gate, p in bench.GATES:
        row = next(r for r in rows if (r["gate"], r["p"], r["ref"]) == (gate, p, "ml_in"))
        for method, (_, _, iterations) in METHODS.items():
            argmax = _vote(bench, x, cov, method, gate, p, 0.0)
            want = bench.summarize(argmax, x, cov, outlier, iterations)
            ours = row["table"][method]
            for key in ("false_positive_votes", "false_negative_votes"):
                assert ours[key] == want[key], (gate, p, method, key)
            assert ours["error_mean_ml_in"] == pytest.approx(want["error_mean_ml_in"], abs=1e-12)
            moved += (_vote(bench, x, cov, method, gate, p, 1e-4).inlier != argmax.inlier).any()
    assert moved  # the tie rule would have decided some of these otherwise


def test_the_table_and_its_readings_are_one_file_replaced_at_once(tmp_path, capsys):
    """The best reading's table and the readings it was picked from are saved together: a
    failure between two files would leave a new table beside old readings."""
    assert load_bench("voting_table1").main(["--trials", "2", "--out", str(tmp_path)]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["results.json"]
    saved = json.loads((tmp_path / "results.json").read_text())
    assert saved["meta"] == {"radius": 0.4, "seed": 0}
    best = min(saved["readings"], key=lambda r: r["score"])
    assert saved["table"]["reading"]["score"] == best["score"]
    assert saved["table"]["details"] == best["table"]
    assert "results.json" in capsys.readouterr().out


def test_a_radius_that_is_no_distance_is_refused_when_parsed(tmp_path, capsys):
    """--radius inf (or nan, 0) was taken: every robot then hears every other, or none."""
    for radius in ("inf", "nan", "0"):
        with pytest.raises(SystemExit) as exc:
            load_bench("voting_table1").main(["--radius", radius, "--out", str(tmp_path)])
        assert exc.value.code == 2
        assert f"argument --radius: '{radius}': expected a finite number above 0" in \
            capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []
