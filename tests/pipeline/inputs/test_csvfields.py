"""Lines of a user's text file: encodings named in one line."""

import pytest

from pipeline.errors import InputError
from pipeline.inputs.csvfields import text_lines


@pytest.mark.parametrize("encoding", ["utf-16", "utf-16-be", "utf-32"])
def test_utf16_and_utf32_text_is_named_with_what_to_do(tmp_path, encoding):
    """A spreadsheet's "Unicode text" export is UTF-16 with a byte-order mark: the message
    says so and asks for UTF-8 (rather than for 'the text file itself')."""
    p = tmp_path / "links.csv"
    text = "cam_i,feat_i,cam_j,feat_j\r\n0,0,1,0\r\n"
    p.write_bytes(("\ufeff" + text).encode(encoding) if encoding == "utf-16-be"
                  else text.encode(encoding))
    with pytest.raises(InputError, match=r"links file '.*links.csv' is not a UTF-8 text file "
                                         r"\(UTF-16 or UTF-32 by its byte-order mark at line 1\); "
                                         r"save it as UTF-8"):
        list(text_lines(p, "links file"))


def test_utf8_with_a_byte_order_mark_is_read(tmp_path):
    p = tmp_path / "links.csv"
    p.write_bytes(b"\xef\xbb\xbf0,0,1,0\r\n1,0,2,0\n")
    assert list(text_lines(p, "links file")) == [(1, "0,0,1,0"), (2, "1,0,2,0")]


def test_a_carriage_return_inside_a_row_says_what_to_do():
    """A file whose lines end with a carriage return alone (classic Mac OS) is one row: the
    message names the carriage return and the line ends to save with, not the csv module's
    advice about a 'universal-newline mode' the user cannot choose."""
    from pipeline.inputs.csvfields import csv_row, line_fields

    for read in (lambda: csv_row("0,0,1,0\r1,0,2,0", "in.csv:1"),
                 lambda: line_fields("0,1\r1,2", "in.csv:1")):
        with pytest.raises(InputError) as exc:
            read()
        msg = str(exc.value)
        assert msg.startswith("in.csv:1: ") and "not a CSV row (a carriage return" in msg
        assert "LF or CRLF" in msg and "universal-newline" not in msg
