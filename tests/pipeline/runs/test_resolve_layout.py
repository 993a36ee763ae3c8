"""resolve's cuts do not depend on how the ids of the links file are spelled
(pipeline.runs.resolve, pipeline.inputs.compact)."""

import csv

import pytest

from pipeline.runs.resolve import resolve_file

# a 3-cycle of equal links (no quality column): the merge rules break the tie
TIED = [(0, 0, 1, 1), (1, 1, 2, 1), (2, 1, 0, 1), (0, 0, 2, 0)]


def _write(path, rows):
    with open(path, "w", newline="") as f:
        csv.writer(f).writerows(rows)


def _statuses(path):
    with open(path) as f:
        return [(r["status"], r["reason"]) for r in csv.DictReader(f)]


@pytest.mark.parametrize("resolution", ["sync", "evidence", "paper"])
def test_cuts_do_not_follow_the_spelling_of_the_ids(tmp_path, resolution):
    # the same links with camera 1's only feature named 0 (compact), 1 (as above) and
    # sparse ids: the same cuts, as a process team (which always runs on compact ids) makes
    spellings = {
        "compact": [(ci, fi if ci != 1 else 0, cj, fj if cj != 1 else 0)
                    for ci, fi, cj, fj in TIED],
        "gap": TIED,
        "sparse": [(3 * ci + 1, 7 * fi + 2, 3 * cj + 1, 7 * fj + 2) for ci, fi, cj, fj in TIED],
    }
    got = {}
    for name, rows in spellings.items():
        _write(tmp_path / f"{name}.csv", rows)
        resolve_file(tmp_path / f"{name}.csv", tmp_path / f"{name}-out.csv",
                     resolution=resolution)
        got[name] = _statuses(tmp_path / f"{name}-out.csv")
    assert got["gap"] == got["compact"]
    assert got["sparse"] == got["compact"]
    assert sum(s == "deleted" for s, _ in got["compact"]) > 0
