"""bench/landmarks_clear.py: input it cannot read is one ``error:`` line, exit status 2, and
the previous results.json stays as it was."""

from benchload import load_bench


def test_a_missing_data_folder_is_one_error_line(tmp_path, capsys):
    (tmp_path / "results.json").write_text('{"previous": true}')
    code = load_bench("landmarks_clear").main(
        ["--data", str(tmp_path / "NOPE"), "--frames", "6", "--graphs", "ring",
         "--configs", "none:none:none", "--out", str(tmp_path)])
    assert code == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {tmp_path / 'NOPE'}: no such folder of labelled images")
    assert "Traceback" not in err
    assert (tmp_path / "results.json").read_text() == '{"previous": true}'
