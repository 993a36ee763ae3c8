"""Fields of one line of a user's text file (comm graphs): CSV quoting, comments, either
comma- or whitespace-separated.

A line is split on commas when it has a comma outside double quotes, otherwise on runs of
spaces or tabs. Double quotes follow CSV (:mod:`csv`): ``"my photo, #2.jpg"`` is one field,
``""`` inside quotes is one quote. ``#`` outside quotes starts a comment.
"""

from __future__ import annotations

import csv

__all__ = ["line_fields"]


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


def line_fields(raw: str) -> list[str]:
    """Non-empty, stripped fields of ``raw``; ``[]`` for a blank or comment line.

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
    fields = next(csv.reader([line], delimiter="," if comma else " ", skipinitialspace=True))
    return [f.strip() for f in fields if f.strip()]
