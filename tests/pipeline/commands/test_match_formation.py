import pytest

from pipeline.__main__ import main
from pipeline.commands.match_formation import ROWS, match_formation, table


@pytest.fixture(scope="module")
def small_a():
    return match_formation("a", seed=0, size=(320, 240), max_features=500)


def test_counts_are_consistent(small_a):
    r = small_a
    assert r["links"] == r["good_links"] + r["spurious_links"] > 0
    assert r["precision"] == pytest.approx(r["good_links"] / r["links"])
    assert r["m_sum"] <= r["features"] == sum(r["features_per_camera"])
    assert r["conflictive_features"] <= r["m_sum"]
    assert r["conflictive_sets"] <= r["association_sets"]
    assert r["comm_edges"] == len(r["edges"])
    assert sum(e["links"] for e in r["edges"]) == r["links"]
    assert all(r[f"time_{s}"] >= 0 for s in ("render", "features", "matching", "evaluate"))


def test_table_has_every_row_and_the_paper_column(small_a):
    md = table([small_a, {**small_a, "formation": "b"}])
    for label, _ in ROWS:
        assert f"| {label} |" in md
    assert "| (a) | (b) |" in md
    assert "2, 22, 31, 72" in md  # paper's conflictive sets, Table III


def test_cli_prints_table(capsys):
    assert main(["match-formation", "--formation", "b", "--size", "320x240",
                 "--max-features", "300", "--features", "orb"]) == 0
    out = capsys.readouterr().out
    assert "Conflictive sets (c)" in out and "Raw precision" in out and "(b)" in out


@pytest.mark.parametrize("argv,match", [
    (["--formation", "z"], "--formation 'z': choose one of a, b, c, d or all"),
    (["--features", "brisk"], "--features 'brisk': choose one of sift, orb, akaze"),
    (["--size", "big"], "--size 'big'"),
    (["--max-features", "3"], "at least 8"),
])
def test_bad_arguments_are_clear_errors(argv, match, capsys):
    assert main(["match-formation", *argv]) == 2
    err = capsys.readouterr().err
    assert match in err and "Traceback" not in err
