"""Lines and fields of a user's text file (links, comm graphs, pairs, label tables).

Lines (:func:`text_lines`, the one reader of these files): UTF-8 (a byte-order mark at the
start is dropped), read line by line; a row ends only at ``\n`` or ``\r\n``, so a form feed,
a vertical tab, U+2028 or any other character inside a row stays inside it (and makes that
row wrong, naming it). A line longer than :data:`MAX_LINE_BYTES` is refused as soon as it is
seen: no row of these files comes near it, and memory stays bounded whatever the file.

Fields (:func:`line_fields`, comm graphs): a line is split on commas when it has a comma
outside double quotes, otherwise on runs of spaces or tabs. Double quotes follow CSV
(:mod:`csv`): ``"my photo, #2.jpg"`` is one field, ``""`` inside quotes is one quote. ``#``
outside quotes starts a comment. :func:`csv_row` splits one CSV row; a row CSV cannot read
(a carriage return inside it) is an InputError naming the file and line.
"""

from __future__ import annotations

import csv
import os
import re
from collections.abc import Iterator

from pipeline.errors import InputError

__all__ = ["MAX_LINE_BYTES", "NUMBER", "csv_row", "line_fields", "text_lines"]

#: longest line of a user's text file, in bytes (a row of these files holds a few numbers or
#: two file names; :mod:`csv` itself stops at fields of 131,072 characters)
MAX_LINE_BYTES = 65536

#: a number as written in a text file: ASCII digits, an optional sign, point and exponent
#: (Python's float() also takes "1_0" (10), other scripts' digits and "infinity")
NUMBER = re.compile(r"[+-]?([0-9]+\.?[0-9]*|\.[0-9]+)([eE][+-]?[0-9]+)?")


def text_lines(path: str | os.PathLike, what: str) -> Iterator[tuple[int, str]]:
    """``(line number, line)`` of each line of ``path``, without its ``\n`` / ``\r\n``.

    Parameters
    ----------
    path : a regular file (checked by the caller)
    what : how the messages name the file, e.g. ``"links file"``

    Raises
    ------
    InputError
        A line longer than :data:`MAX_LINE_BYTES`, or one that is not UTF-8 (naming it).
    """
    with open(path, "rb") as f:
        lineno = 0
        while raw := f.readline(MAX_LINE_BYTES + 1):
            lineno += 1
            if len(raw) > MAX_LINE_BYTES and not raw.endswith(b"\n"):
                raise InputError(f"{what} {os.fspath(path)!r}, line {lineno}: longer than "
                                 f"{MAX_LINE_BYTES} bytes; a row of this file is a short line "
                                 "of text: is it the right file?")
            if lineno == 1 and raw.startswith(b"\xef\xbb\xbf"):
                raw = raw[3:]
            if lineno == 1 and raw[:2] in (b"\xff\xfe", b"\xfe\xff"):
                # UTF-16 (or UTF-32) text, e.g. a spreadsheet's "Unicode text" export
                raise InputError(f"{what} {os.fspath(path)!r} is not a UTF-8 text file "
                                 "(UTF-16 or UTF-32 by its byte-order mark at line 1); save "
                                 "it as UTF-8")
            try:
                line = raw.decode("utf-8")
            except UnicodeDecodeError as exc:
                raise InputError(f"{what} {os.fspath(path)!r} is not a UTF-8 text file "
                                 f"({exc.reason} at line {lineno}); give the text file "
                                 "itself") from None
            yield lineno, line.removesuffix("\n").removesuffix("\r")


def csv_row(line: str, where: str, **fmt) -> list[str]:
    """The fields of one CSV row ``line`` (``fmt``: :func:`csv.reader` options); InputError
    naming ``where`` (e.g. ``FILE:LINE``) when CSV cannot read it."""
    try:
        return next(csv.reader([line], **fmt), [])
    except csv.Error:
        # the one row csv refuses here: a carriage return outside quotes (its own message
        # asks for a "universal-newline mode" the user cannot choose)
        raise InputError(f"{where}: {line[:80]!r}: not a CSV row (a carriage return inside "
                         "it); a row ends only with a line break, \\n or \\r\\n: lines "
                         "ended by a carriage return alone (classic Mac OS) are one line here, "
                         "save the file with LF or CRLF line ends") from None


def _uncomment(line: str) -> tuple[str, bool]:
    """``line`` without its comment, unquoted tabs made spaces; and whether it has an
    unquoted comma."""
    out, quoted, comma = [], False, False
    for ch in line:
        if ch == '"':
            quoted = not quoted
        elif not quoted:
            if ch == "#":
                break
            if ch == ",":
                comma = True
            if ch == "\t":
                ch = " "
        out.append(ch)
    return "".join(out), comma


def line_fields(raw: str, where: str = "graph file", keep_blank: bool = False) -> list[str]:
    """Non-empty, stripped fields of ``raw``; ``[]`` for a blank or comment line (``where``
    names the line in an error). With ``keep_blank`` a field that is empty or only spaces
    (``a,,b``, ``" " b``) is kept, as ``''``, for the caller to refuse.

    Examples
    --------
    >>> line_fields('a.jpg, "my photo, #2.jpg"  # a comment')
    ['a.jpg', 'my photo, #2.jpg']
    >>> line_fields('0\\t"b c.png"')
    ['0', 'b c.png']
    >>> line_fields("  # only a comment")
    []
    """
    line, comma = _uncomment(raw)
    line = line.strip()
    if not line:
        return []
    fields = csv_row(line, where, delimiter="," if comma else " ", skipinitialspace=True)
    return [f.strip() for f in fields if keep_blank or f.strip()]
