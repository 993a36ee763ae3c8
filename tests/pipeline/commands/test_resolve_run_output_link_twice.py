"""A run-output links.csv holding one link twice (once deleted, once kept) is a damaged file:
resolve refuses it naming both rows, as it refuses a repeated link in a plain links file,
rather than resolve both rows and write the link twice."""
import pytest

from pipeline.__main__ import main

_HEADER = "cam_i,feat_i,cam_j,feat_j,status,reason,round,truth\n"


@pytest.mark.parametrize("rows, line, other", [
    ("0,1,1,2,deleted,conflictive,3,\n0,1,1,2,kept,,,\n1,2,2,3,kept,,,\n", 3, 2),
    ("0,1,1,2,kept,,,\n1,2,2,3,kept,,,\n1,2,0,1,deleted,conflictive,3,\n", 4, 2),
])
def test_a_run_output_with_a_link_twice_is_refused_naming_both_rows(tmp_path, capsys, rows,
                                                                    line, other):
    src, out = tmp_path / "links.csv", tmp_path / "out.csv"
    src.write_text(_HEADER + rows)
    assert main(["resolve", "--links", str(src), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"links.csv:{line}: " in err and f"duplicate link (the same link as row {other}: " in err
    assert "a run-output links.csv lists every link once" in err
    assert not out.exists()


def test_a_run_output_keeps_a_deleted_row_that_breaks_one_to_one(tmp_path):
    src, out = tmp_path / "links.csv", tmp_path / "out.csv"
    src.write_text(_HEADER + "0,1,1,2,deleted,not-one-to-one,,\n0,1,1,3,kept,,,\n")
    assert main(["resolve", "--links", str(src), "--out", str(out)]) == 0
    assert out.read_text().splitlines()[1:] == ["0,1,1,2,deleted,not-one-to-one,,",
                                                "0,1,1,3,kept,,,"]
