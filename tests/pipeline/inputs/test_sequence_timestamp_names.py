"""Frames named by timestamps with decimals (``1700000000.15.png``, as a float's text writes
them, without trailing zeros): name order is time order, so no number-order warning, and
the zero-padding advice keeps a number's decimals as they are."""

import shutil
from pathlib import Path

from pipeline.inputs.sequence import load_sequence

SCEAUX = Path(__file__).parents[2] / "data" / "sceaux_castle_640"


def _folder(root: Path, names: list[str]) -> Path:
    files = sorted(SCEAUX.glob("*.JPG"))
    for r, robot in enumerate(("a", "b")):
        (root / robot).mkdir(parents=True)
        for k, name in enumerate(names):
            shutil.copy(files[3 * r + k], root / robot / name)
    return root


def test_decimal_timestamps_in_time_order_are_not_warned(tmp_path, caplog):
    # .1 < .15 < .2 by name and by time; read as integers after the point, 15 > 2 warned
    # 'zero-pad the numbers (e.g. 1700000000.002.png)', which would put .2 before .15
    names = ["1700000000.1.png", "1700000000.15.png", "1700000000.2.png"]
    with caplog.at_level("WARNING"):
        seq = load_sequence(_folder(tmp_path / "seq", names), max_size=64)
    assert [v.name for v in seq.views[::2]] == [f"a/{n}" for n in names]
    assert "by number" not in caplog.text


def test_decimals_out_of_number_order_keep_their_fraction_in_the_advice(tmp_path, caplog):
    with caplog.at_level("WARNING"):
        load_sequence(_folder(tmp_path / "seq", ["t10.5.png", "t2.25.png"]), max_size=64)
    assert "(a/t10.5.png before a/t2.25.png)" in caplog.text
    assert "(e.g. t002.25.png)" in caplog.text


def test_dotted_dates_are_numbers_each_and_still_warned(tmp_path, caplog):
    # 2024.12.01 sorts before 2024.2.01 by name; read as 2024.12 < 2024.2 it would pass
    with caplog.at_level("WARNING"):
        load_sequence(_folder(tmp_path / "seq", ["2024.12.01.png", "2024.2.01.png"]),
                      max_size=64)
    assert "(a/2024.12.01.png before a/2024.2.01.png)" in caplog.text
    assert "(e.g. 2024.002.001.png)" in caplog.text
