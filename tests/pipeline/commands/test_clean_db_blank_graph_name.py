"""clean-db --comm-graph: a row whose image name is blank (empty or only spaces) is refused,
naming the file, the line and the column.

``" ",view_1.jpg`` was refused as a row of 1 column, a row that holds two; ``view_0.jpg, ,
view_2.jpg`` was read as the edge view_0.jpg - view_2.jpg; a row ``" "`` alone was skipped.
"""

import sys
from pathlib import Path

import pytest

from pipeline.__main__ import main

sys.path.insert(0, str(Path(__file__).parent))
from hostile import one_line_error  # noqa: E402
from test_clean_db import _db_with_planted_conflicts  # noqa: E402


@pytest.mark.parametrize("row, column", [
    ('" ",view_1.jpg', "cam_i"),
    ('view_1.jpg," "', "cam_j"),
    ("view_0.jpg, ,view_2.jpg", "cam_j"),
    ("view_0.jpg,,view_2.jpg", "cam_j"),
    ("view_0.jpg,", "cam_j"),
    ('" "', "cam_i"),
    ('"   " view_2.jpg', "cam_i"),
])
def test_blank_image_name_is_refused(tmp_path, capsys, row, column):
    src = tmp_path / "in.db"
    _db_with_planted_conflicts(src)
    graph = tmp_path / "g.csv"
    graph.write_text(f"view_0.jpg,view_1.jpg\n{row}\n")
    out = tmp_path / "o.db"
    argv = ["clean-db", str(src), "--out", str(out), "--comm-graph", str(graph), "--no-rerun"]
    assert main(argv) == 2
    one_line_error(capsys, f"{graph}, line 2: {row!r}: {column} is a blank image name",
                   "write the image's name or its index there, or delete the line")
    assert not out.exists()


def test_trailing_comma_is_still_read(tmp_path, capsys):
    src = tmp_path / "in.db"
    _db_with_planted_conflicts(src)
    graph = tmp_path / "g.csv"
    graph.write_text("view_0.jpg,view_1.jpg,\nview_1.jpg,view_2.jpg,,\nview_2.jpg,view_3.jpg\n")
    argv = ["clean-db", str(src), "--out", str(tmp_path / "o.db"), "--comm-graph", str(graph),
            "--no-rerun"]
    assert main(argv) == 0
    assert "4 images, 3 comm edges" in capsys.readouterr().out
