"""``resolve`` dropped its input's quality column: the links.csv it wrote had none, so its own
output given back to it (which it reads) weighed every link alike. The quality now goes
through as a last column ``quality``, the same float64 read back; an input without one gives
the run-output columns as before."""

import csv

import numpy as np
import pytest

from pipeline.__main__ import main
from pipeline.errors import InputError
from pipeline.inputs.linkscsv import RUN_LINK_COLUMNS, read_links_csv, read_run_links_csv

# Fig. 1 of the paper with a quality per link (the last row given with cam_i > cam_j)
QUALITY = [0.9, 0.8, 0.123456789012345678, 1e-05]
FIG1_Q = "cam_i,feat_i,cam_j,feat_j,quality\n" + "".join(
    f"{row},{q!r}\n" for row, q in zip(["0,0,3,1", "0,0,1,0", "1,0,2,0", "3,0,2,0"], QUALITY,
                                       strict=True))


def _rows(path):
    with open(path, newline="") as f:
        return list(csv.reader(f))


def test_the_quality_column_goes_through(tmp_path, capsys):
    src, out = tmp_path / "in.csv", tmp_path / "out.csv"
    src.write_text(FIG1_Q)
    assert main(["resolve", "--links", str(src), "--out", str(out)]) == 0
    rows = _rows(out)
    assert tuple(rows[0]) == (*RUN_LINK_COLUMNS, "quality")
    assert [float(r[8]) for r in rows[1:]] == QUALITY  # exactly, in input order
    back = read_run_links_csv(out)
    np.testing.assert_array_equal(back.links.quality, QUALITY)
    assert back.status.tolist().count("deleted") == 1
    lf = read_links_csv(out)
    assert lf.has_quality
    np.testing.assert_array_equal(lf.links.quality, QUALITY)


def test_its_own_output_given_back_keeps_the_quality(tmp_path, capsys):
    src, out, again = tmp_path / "in.csv", tmp_path / "out.csv", tmp_path / "again.csv"
    src.write_text(FIG1_Q)
    assert main(["resolve", "--links", str(src), "--out", str(out)]) == 0
    assert main(["resolve", "--links", str(out), "--out", str(again)]) == 0
    assert again.read_text() == out.read_text()


def test_an_input_without_quality_writes_the_run_columns(tmp_path, capsys):
    src, out = tmp_path / "in.csv", tmp_path / "out.csv"
    src.write_text("0,0,3,1\n0,0,1,0\n1,0,2,0\n3,0,2,0\n")
    assert main(["resolve", "--links", str(src), "--out", str(out)]) == 0
    rows = _rows(out)
    assert tuple(rows[0]) == RUN_LINK_COLUMNS and {len(r) for r in rows} == {8}
    assert not read_links_csv(out).has_quality


@pytest.mark.parametrize("reader", [read_links_csv, read_run_links_csv])
@pytest.mark.parametrize("bad", ["nan", "x", ""])
def test_a_bad_quality_in_the_run_output_is_named(tmp_path, reader, bad):
    src = tmp_path / "in.csv"
    src.write_text(",".join((*RUN_LINK_COLUMNS, "quality")) + f"\n0,0,1,0,kept,,,,{bad}\n")
    with pytest.raises(InputError, match=rf"in.csv:2: .*quality '{bad}' is not a"):
        reader(src)


def test_a_run_output_row_without_its_quality_is_named(tmp_path):
    src = tmp_path / "in.csv"
    src.write_text(",".join((*RUN_LINK_COLUMNS, "quality")) + "\n0,0,1,0,kept,,,\n")
    with pytest.raises(InputError, match=r"in.csv:2: .* has 8 columns; the header names 9 "
                                         r"\(.*,truth,quality\)"):
        read_links_csv(src)
