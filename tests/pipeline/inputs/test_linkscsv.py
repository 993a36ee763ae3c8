"""Strict reading of users' links files; atomic run-output links.csv."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pipeline.errors import InputError
from pipeline.inputs.linkscsv import (
    RUN_LINK_COLUMNS,
    features_per_camera_for,
    read_links_csv,
    read_run_links_csv,
    write_links_csv,
)
from pipeline.types import LinkLedger, Links


def write(tmp_path, text, name="in.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_reads_header_quality_comments_and_swaps_ends(tmp_path):
    p = write(tmp_path, "cam_i,feat_i,cam_j,feat_j,quality\n# a comment\n0,1,1,2,0.5\n\n"
                        "2, 7, 1, 3, 0.25\n")
    lf = read_links_csv(p)
    assert lf.has_quality
    assert lf.links.cam_i.tolist() == [0, 1] and lf.links.feat_i.tolist() == [1, 3]
    assert lf.links.cam_j.tolist() == [1, 2] and lf.links.feat_j.tolist() == [2, 7]
    assert lf.links.quality.tolist() == [0.5, 0.25]
    assert lf.line.tolist() == [3, 5]
    assert features_per_camera_for(lf.links).tolist() == [2, 4, 8]
    assert features_per_camera_for(lf.links, n_cameras=5).tolist() == [2, 4, 8, 0, 0]


def test_reads_without_header_and_quality(tmp_path):
    lf = read_links_csv(write(tmp_path, "0,0,1,0\n1,0,2,0\n"))
    assert not lf.has_quality and len(lf.links) == 2
    assert (lf.links.quality == 1.0).all()


@pytest.mark.parametrize("text, line, message", [
    ("0,0,1,0\n0,x,1,1\n", 2, "'x' is not an integer"),
    ("0,0,1,0\n0,1.5,1,1\n", 2, "not an integer"),
    # what Python's int() would take: an underscore, a sign, another script's digits
    ("1_0,0,2,0\n", 1, "cam_i '1_0' is not an integer id"),
    ("+1,0,2,0\n", 1, r"cam_i '\+1' is not an integer id"),
    ("0,0,2,1e3\n", 1, "feat_j '1e3' is not an integer id"),
    ("\uff11,0,2,0\n", 1, "is not an integer id; ids are 0-based integers written in digits"),
    ("0,0,1,-1\n", 1, "negative"),
    ("0,0,1\n", 1, "has 3 columns"),
    ("0\t0\t1\t0\n", 1, "has 1 column; .* separated by commas, not tabs"),
    ("0;0;1;0\n", 1, "has 1 column; .* separated by commas, not semicolons"),
    ("0,0,1,0,0.5,7\n", 1, "has 6 columns"),
    ("0,0,1,0,0.5\n0,1,1,1\n", 2, "started with 5"),
    ("0,0,1,0,abc\n", 1, "quality 'abc'"),
    ("0,0,1,0,nan\n", 1, "quality 'nan'"),
    # Python's float() reads these as 10 and 3: a quality is written in ASCII digits
    ("0,0,1,0,1_0\n", 1, "quality '1_0' is not a number written in digits 0-9"),
    ("0,0,1,0,\u0663\n", 1, "quality '\u0663' is not a number written in digits 0-9"),
    ("0,0,1,0,0.5\n1,0,2,0, infinity\n", 2, "quality 'infinity' is not a finite number"),
    ("0,0,1,0\n2,3,2,4\n", 2, "self-link within camera 2"),
    ("0,0,1,0\n0,1,1,1\n1,0,0,0\n", 3, "duplicate link"),
    ("0,0,1,0\n0,0,1,1\n", 2, "feature 0,0 is linked twice to camera 1"),
    ("0,0,1,5\n0,1,1,5\n", 2, "feature 1,5 is linked twice to camera 0"),
    ("cam_i,cam_j,feat_i,feat_j\n0,0,1,0\n", 1, "header"),
    # a header in another order named the first column name as a bad id ('cam_i 'cam_j'...')
    ("cam_j,feat_j,cam_i,feat_i\n0,0,1,0\n", 1, "header 'cam_j,feat_j,cam_i,feat_i' must be"),
    ("feat_i,cam_i,feat_j,cam_j,quality\n0,0,1,0,1\n", 1, "header"),
])
def test_bad_rows_are_named(tmp_path, text, line, message):
    p = write(tmp_path, text)
    with pytest.raises(InputError, match=message) as err:
        read_links_csv(p)
    assert f"in.csv:{line}:" in str(err.value)


def test_duplicate_error_names_both_rows(tmp_path):
    p = write(tmp_path, "0,0,1,0\n0,1,1,1\n1,0,0,0\n")
    with pytest.raises(InputError, match="also row 1"):
        read_links_csv(p)


def test_missing_file(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        read_links_csv(tmp_path / "nope.csv")


def test_run_links_csv_round_trip_and_atomic(tmp_path):
    links = Links([0, 0, 1], [0, 1, 2], [1, 2, 2], [3, 4, 5])
    out = tmp_path / "run" / "links.csv"
    write_links_csv(out, LinkLedger(links, np.array(["kept", "deleted", "kept"], dtype=object),
                                    ["", "resolution", ""], [-1, 2, -1], [-1, 1, -1],
                                    ["", "b", ""], np.array([1, 0, -1], dtype=np.int8)))
    lines = out.read_text().splitlines()
    assert lines[0] == ",".join(RUN_LINK_COLUMNS)
    assert lines[1:] == ["0,0,1,3,kept,,,1", "0,1,2,4,deleted,resolution,2,0", "1,2,2,5,kept,,,"]
    back = read_run_links_csv(out)
    assert back.links.feat_j.tolist() == [3, 4, 5]
    assert back.round.tolist() == [-1, 2, -1] and back.truth.tolist() == [1, 0, -1]
    assert back.status.tolist() == ["kept", "deleted", "kept"]
    assert [p.name for p in out.parent.iterdir()] == ["links.csv"]  # no temp file left
    with pytest.raises(ValueError, match="status"):
        write_links_csv(out, LinkLedger(links, ["kept", "gone", "kept"], ["", "", ""],
                                        [-1, -1, -1], [-1, -1, -1], ["", "", ""]))
    assert read_run_links_csv(out).status.tolist() == ["kept", "deleted", "kept"]  # intact



@pytest.mark.parametrize("row, said", [
    ("0,1,1,2", "has 4 columns"),                       # a row cut short
    ("0,1,1,2,kept,,,1,extra", "has 9 columns"),        # one too many
    ("zz,1,1,2,kept,,,1", "cam_i 'zz' is not an integer id"),
    ("0,-3,1,2,kept,,,1", "feat_i -3 is negative"),
    ("0,1,1,2,deleted,resolution,r2,", "round 'r2' is not a round number"),
    ("0,1,1,2,kept,,,yes", "truth 'yes' is not 1"),
])
def test_a_bad_row_of_a_run_links_csv_is_named_not_a_traceback(tmp_path, row, said):
    """A run's links.csv read back (viz.saved_run) with a row of the wrong width or a
    non-integer field raised IndexError / ValueError; now an InputError naming the file, the
    line and the value."""
    p = write(tmp_path, ",".join(RUN_LINK_COLUMNS) + "\n0,5,1,6,kept,,,1\n" + row + "\n",
              name="links.csv")
    with pytest.raises(InputError, match=f"links.csv:3: .*{said}"):
        read_run_links_csv(p)


def test_a_blank_line_in_a_run_links_csv_is_skipped(tmp_path):
    p = write(tmp_path, ",".join(RUN_LINK_COLUMNS) + "\n0,5,1,6,kept,,,1\n\n",
              name="links.csv")
    assert read_run_links_csv(p).links.feat_j.tolist() == [6]

def test_huge_ids_are_named_not_overflowing(tmp_path):
    """Regression: a 20-digit id raised OverflowError deep inside numpy (found by fuzzing)."""
    with pytest.raises(InputError, match="feat_j .* is too large"):
        read_links_csv(write(tmp_path, "0,0,1,99999999999999999999\n"))


_FIELDS = ["0", "1", "2", "3", "7", "+4", "12", "-1", "1.5", "", "1e3", " 2", "2147483647",
           "2147483646", "99999999999999999999", "0.25", "1e999", "x", '"3"']


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(rows=st.lists(st.lists(st.sampled_from(_FIELDS), min_size=3, max_size=6), max_size=8),
       header=st.sampled_from(["", "cam_i,feat_i,cam_j,feat_j\n",
                               "cam_i,feat_i,cam_j,feat_j,quality\n", "CAM_I, feat_i,cam_j,feat_j\n",
                               "\ufeffcam_i,feat_i,cam_j,feat_j\n", "cam_i,cam_j,feat_i,feat_j\n"]),
       end=st.sampled_from(["\n", "\r\n"]), last=st.booleans())
def test_plain_files_read_at_once_as_row_by_row(tmp_path, monkeypatch, rows, header, end, last):
    """The NumPy reading of a plain file (``_read_plain``) gives what the row reader gives:
    the same links, lines and quality, or the row reader's error when a row is bad."""
    import pipeline.inputs.linkscsv as lc

    text = header.replace("\n", end) + end.join(",".join(r) for r in rows) + (end if last else "")
    p = tmp_path / "in.csv"
    p.write_bytes(text.encode())

    def read(fast):
        with monkeypatch.context() as m:
            if not fast:
                m.setattr(lc, "_read_plain", lambda path: None)
            try:
                lf = lc.read_links_csv(p)
            except InputError as exc:
                return str(exc)
        q = None if lf.links.quality is None else lf.links.quality.tolist()
        return ([c.tolist() for c in (lf.links.cam_i, lf.links.feat_i, lf.links.cam_j,
                                      lf.links.feat_j)], q, lf.line.tolist(), lf.has_quality)

    assert read(True) == read(False)


def test_a_large_plain_file_is_read_at_once(tmp_path, monkeypatch):
    """A plain file of many rows takes the NumPy path (the row reader is not called)."""
    import pipeline.inputs.linkscsv as lc

    n = 2000
    rows = "\n".join(f"{c},{f},{c + 1},{(f * 7) % n},{f / n}" for c in range(3) for f in range(n))
    p = write(tmp_path, "cam_i,feat_i,cam_j,feat_j,quality\n" + rows + "\n")
    monkeypatch.setattr(lc, "_rows", lambda path: pytest.fail("row reader used"))
    lf = lc.read_links_csv(p)
    assert len(lf.links) == 3 * n and lf.line[[0, -1]].tolist() == [2, 3 * n + 1]
    assert lf.links.quality[5] == 5 / n


@pytest.mark.parametrize(("value", "said"), [
    ("x", "round 'x' is not a round number; rounds are 0-based integers written in digits 0-9 "
          "(or empty: none)"),
    ("-3", "round -3 is negative; rounds are 0-based (or empty: none)"),
])
def test_a_bad_round_of_a_run_links_csv_is_named_as_a_round(tmp_path, value, said):
    """The round column of a run-output links.csv read back is a round number that may be
    empty: its message says so, not that an id is expected."""
    p = tmp_path / "links.csv"
    p.write_text("cam_i,feat_i,cam_j,feat_j,status,reason,round,truth\n"
                 f"0,1,1,1,deleted,resolution,{value},\n")
    with pytest.raises(InputError) as exc:
        read_links_csv(p)
    assert said in str(exc.value) and " id" not in str(exc.value)
