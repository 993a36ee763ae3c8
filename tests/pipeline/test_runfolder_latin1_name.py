"""An output whose name is not UTF-8 (Latin-1 bytes, e.g. ``resolve --out $'r\\xe9.csv'``):
the temporary file's digest encoded the name as UTF-8, so resolve, clean-db and clean-h5 ended
in a UnicodeEncodeError traceback before writing anything."""

import os

from pipeline.runfolder import OutputFiles, atomic_file


def test_an_output_under_a_latin1_name_is_written(tmp_path):
    target = tmp_path / os.fsdecode(b"r\xe9sum\xe9.csv")
    with atomic_file(target) as f:
        f.write("a,b\n")
    assert os.listdir(os.fsencode(tmp_path)) == [b"r\xe9sum\xe9.csv"]
    assert target.read_text() == "a,b\n"


def test_output_files_under_latin1_names(tmp_path):
    folder = tmp_path / os.fsdecode(b"caf\xe9")
    folder.mkdir()
    with OutputFiles(replace=True) as out:
        out.path(folder / os.fsdecode(b"\xe9.db")).write_bytes(b"db")
    assert os.listdir(os.fsencode(folder)) == [b"\xe9.db"]
