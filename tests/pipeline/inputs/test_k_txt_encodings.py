"""A K.txt saved as UTF-16 (Notepad's or a spreadsheet's "Unicode") was refused as "not a text
file ('utf-8' codec can't decode byte 0xff in position 0 …)", which it is, without saying
what to do; it is now named UTF-16, with the advice to save it as UTF-8. A UTF-8 file with a
byte-order mark, and Windows line ends, are read as before."""

import pytest

from pipeline.errors import InputError
from pipeline.inputs.photos import read_k_txt

MATRIX = "300 0 159.5\n0 300 119.5\n0 0 1\n"


def test_a_utf16_k_txt_is_named_with_what_to_do(tmp_path):
    path = tmp_path / "K.txt"
    path.write_bytes(MATRIX.encode("utf-16"))
    with pytest.raises(InputError) as err:
        read_k_txt(path)
    assert str(err.value) == (
        f"intrinsics file {str(path)!r} is not a UTF-8 text file (UTF-16 or UTF-32 by its "
        "byte-order mark at line 1); save it as UTF-8")


def test_a_latin1_byte_is_named_with_its_line(tmp_path):
    path = tmp_path / "K.txt"
    path.write_bytes(MATRIX.encode() + "# caméra\n".encode("latin-1"))
    with pytest.raises(InputError, match=r"is not a UTF-8 text file \(invalid continuation "
                                         r"byte at line 4\)"):
        read_k_txt(path)


@pytest.mark.parametrize("raw", [b"\xef\xbb\xbf" + MATRIX.encode(),
                                 MATRIX.replace("\n", "\r\n").encode()],
                         ids=["utf8-bom", "crlf"])
def test_utf8_with_a_bom_or_windows_line_ends_is_read(tmp_path, raw):
    path = tmp_path / "K.txt"
    path.write_bytes(raw)
    assert read_k_txt(path).tolist() == [[300, 0, 159.5], [0, 300, 119.5], [0, 0, 1]]
