"""bench/landmarks_clear.py: input it cannot read is one ``error:`` line, exit status 2, and
the previous results.json stays as it was."""

import subprocess
import sys
from pathlib import Path

import pytest
from benchload import load_bench

ROOT = Path(__file__).resolve().parents[2]


def test_a_missing_data_folder_is_one_error_line(tmp_path, capsys):
    (tmp_path / "results.json").write_text('{"previous": true}')
    code = load_bench("landmarks_clear").main(
        ["--data", str(tmp_path / "NOPE"), "--frames", "6", "--graphs", "ring",
         "--configs", "none:none:none", "--out", str(tmp_path)])
    assert code == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: --data {tmp_path / 'NOPE'}: no such folder")
    assert "Traceback" not in err
    assert (tmp_path / "results.json").read_text() == '{"previous": true}'


@pytest.mark.parametrize("conf", ["votes", "votes:x:none", "votes:none:epipolar:abc"])
def test_a_config_that_does_not_read_is_refused_before_the_table(tmp_path, capsys, conf):
    with pytest.raises(SystemExit) as exc:
        load_bench("landmarks_clear").main(["--configs", conf, "--out", str(tmp_path)])
    assert exc.value.code == 2
    out, err = capsys.readouterr()
    assert f"error: --configs {conf!r}: expected REFINE:RATIO:GEOMETRY[:PX]" in err
    assert "Traceback" not in err and out == ""


def test_help_is_not_preceded_by_the_table_header():
    proc = subprocess.run([sys.executable, str(ROOT / "bench" / "landmarks_clear.py"), "--help"],
                          capture_output=True, text=True, check=True)
    assert proc.stdout.startswith("usage: ")


@pytest.mark.parametrize("results, message", [
    ("", "--results '': give a file name, saved under --out"),
    ("../escaped.json", "--results '../escaped.json': give a file name, saved under --out"),
    ("sub", "--results 'sub': '{out}/sub' is a folder; give another file name"),
])
def test_a_results_name_it_cannot_save_under_is_refused_before_any_run(tmp_path, capsys,
                                                                       results, message):
    # refused only when saving, after every run had been made (and written under --out)
    out = tmp_path / "out"
    (out / "sub").mkdir(parents=True)
    with pytest.raises(SystemExit) as exc:
        load_bench("landmarks_clear").main(
            ["--data", str(ROOT / "tests" / "data" / "cmu_hotel_small"), "--frames", "3",
             "--graphs", "ring", "--configs", "none:none:none", "--out", str(out),
             "--results", results])
    assert exc.value.code == 2
    captured = capsys.readouterr()
    assert message.format(out=out) in captured.err and "Traceback" not in captured.err
    assert captured.out == "" and [p.name for p in out.iterdir()] == ["sub"]
    assert not (tmp_path / "escaped.json").exists()
