"""A command printing the path of an output whose name is not UTF-8 (Latin-1 bytes) on a
stdout that refuses such bytes (a UTF-8 locale, e.g. en_US.UTF-8): the output was written and
the command then ended in a UnicodeEncodeError traceback."""

import io
import os
import sys

from pipeline.__main__ import main


def test_the_line_naming_a_latin1_output_prints_its_bytes(tmp_path, monkeypatch):
    links = tmp_path / "links.csv"
    links.write_text("0,0,1,0\n1,0,2,0\n")
    out = tmp_path / os.fsdecode(b"r\xe9sum\xe9.csv")
    terminal = io.TextIOWrapper(io.BytesIO(), encoding="utf-8", errors="strict")
    monkeypatch.setattr(sys, "stdout", terminal)
    assert main(["resolve", "--links", str(links), "--out", str(out)]) == 0
    terminal.flush()
    assert b"written: " + os.fsencode(out) + b"\n" in terminal.buffer.getvalue()
