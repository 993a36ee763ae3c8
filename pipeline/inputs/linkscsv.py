"""Links as CSV: the user's own links in, the run-output ``links.csv`` out.

Input (``read_links_csv``): one link per row ``cam_i,feat_i,cam_j,feat_j[,quality]``, 0-based
integer ids, an optional header row naming those columns, blank lines and ``#`` comment lines
allowed. Validation is strict and never drops input silently: a non-integer or negative id, a
bad quality, a wrong number of columns, a self-link, a duplicate link or a link that breaks
one-to-one-ness (Assumption 2.2 of Aragüés et al.) is an :class:`~pipeline.errors.InputError`
naming the file, the row number and its content (in a run-output ``links.csv`` read back,
one-to-one-ness and duplicates are checked on its kept rows: its deleted rows stay deleted, and
``clean-db`` / ``clean-h5`` delete the rows that break one-to-one-ness). A row with ``cam_i > cam_j`` is normalised by
swapping its two ends (docs/DESIGN.md: each undirected link is stored once with ``cam_i < cam_j``).

Output (``write_links_csv``): the ``links.csv`` of docs/DESIGN.md "Run outputs", header
``cam_i,feat_i,cam_j,feat_j,status,reason,round,truth``, written atomically (temp file in the
same folder, then ``os.replace``); with ``quality=True`` (``resolve`` of a links file that has
a quality column) a last column ``quality`` too, which both readers read back.
"""

from __future__ import annotations

import csv
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.errors import InputError
from pipeline.inputs.csvfields import NUMBER
from pipeline.outputs import require_input_file
from pipeline.runfolder import atomic_file
from pipeline.types import LinkLedger, Links

__all__ = [
    "LINK_COLUMNS",
    "RUN_LINK_COLUMNS",
    "RUN_LINK_QUALITY_COLUMNS",
    "LinksFile",
    "read_links_csv",
    "features_per_camera_for",
    "write_links_csv",
    "read_run_links_csv",
]

LINK_COLUMNS = ("cam_i", "feat_i", "cam_j", "feat_j", "quality")
RUN_LINK_COLUMNS = ("cam_i", "feat_i", "cam_j", "feat_j", "status", "reason", "round", "truth")
#: the run-output columns with each link's quality last (``resolve`` keeps its input's)
RUN_LINK_QUALITY_COLUMNS = (*RUN_LINK_COLUMNS, "quality")


@dataclass
class LinksFile:
    """A validated links file.

    Attributes
    ----------
    links : Links, (L,) — normalised, ``cam_i < cam_j``, in file order
    line : ndarray, (L,) int — 1-based line number of each link in the file
    has_quality : bool — the file had a quality column (else quality is 1.0)
    """

    links: Links
    line: np.ndarray
    has_quality: bool
    #: for a run-output links.csv read back as input (its own output, e.g. of ``resolve``):
    #: ``status``, ``reason`` (str) and ``round`` (int, -1 where empty) of every row; else None
    status: np.ndarray | None = None
    reason: np.ndarray | None = None
    round: np.ndarray | None = None
    #: its ``truth`` column (int8: 1 good, 0 spurious, -1 empty), None when every row is empty
    truth: np.ndarray | None = None


def _rows(path: Path):
    """Yield ``(line number, fields, raw text)`` of the data rows (rows end only at ``\n`` or
    ``\r\n``, :func:`pipeline.inputs.csvfields.text_lines`)."""
    from pipeline.inputs.csvfields import csv_row, text_lines

    require_input_file(path, "links file")
    for lineno, raw in text_lines(path, "links file"):
        stripped = raw.strip()
        if not stripped or stripped.startswith("#"):
            continue
        fields = [f.strip() for f in csv_row(stripped, f"{path}:{lineno}")]
        yield lineno, fields, stripped


_ID = re.compile(r"-?[0-9]+")

#: largest camera or feature id accepted (ids index int32 arrays inside the robots)
MAX_ID = 2**31 - 2


def _int_field(path, lineno, raw, name, value) -> int:
    """An id column's value (or the ``round`` column of a run-output links.csv: a 0-based
    round number, named as such in the messages)."""
    what, kind = ("a round number", "rounds") if name == "round" else ("an integer id", "ids")
    empty = " (or empty: none)" if name == "round" else ""
    # ASCII digits only: Python's int() also takes "1_0" (10), "+1" and other scripts' digits
    if not _ID.fullmatch(value):
        raise InputError(f"{path}:{lineno}: {raw!r}: {name} {value!r} is not {what}; "
                         f"{kind} are 0-based integers written in digits 0-9{empty}")
    v = int(value)
    if v < 0:
        raise InputError(f"{path}:{lineno}: {raw!r}: {name} {v} is negative; {kind} are "
                         f"0-based{empty}")
    if v > MAX_ID:
        raise InputError(f"{path}:{lineno}: {raw!r}: {name} {v} is too large; {kind} must be "
                         f"at most {MAX_ID}")
    return v


def _first_duplicate(*cols: np.ndarray) -> tuple[int, int] | None:
    """Positions of the first two rows equal in all ``cols`` (in file order), or None."""
    if cols[0].size < 2:
        return None
    order = np.lexsort((np.arange(cols[0].size),) + tuple(cols[::-1]))
    same = np.ones(order.size - 1, dtype=bool)
    for c in cols:
        cs = c[order]
        same &= cs[1:] == cs[:-1]
    hit = np.flatnonzero(same)
    if hit.size == 0:
        return None
    # report the pair whose second row comes first in the file
    pairs = np.stack([order[hit], order[hit + 1]], axis=1)
    k = int(np.argmin(pairs[:, 1]))
    return int(pairs[k, 0]), int(pairs[k, 1])


#: bytes a data row of the fast path (:func:`_read_plain`) may hold: digits and the signs of
#: numbers, commas, line ends
_PLAIN = b"0123456789,.-+eE\r\n"


def _read_plain(path: Path) -> LinksFile | None:
    """A plain links file read at once with NumPy, or None for :func:`read_links_csv`'s row by
    row reading (which names the row of any error).

    Plain: ASCII rows of 4 or 5 numeric fields, the same count on every row, an optional
    first header row of the column names (a run-output header goes the other way), no blank
    or comment line, no space or quote, line ends ``\n`` or ``\r\n`` only; and nothing
    the row reader refuses (an id that is not a non-negative integer up to :data:`MAX_ID`, a
    non-finite quality, a self-link, a duplicate or not one-to-one link: any of them sends the
    file to the row reader, whose message names the row). Same result as the row reader."""
    from pipeline.inputs.csvfields import MAX_LINE_BYTES

    require_input_file(path, "links file")
    data = path.read_bytes()
    data = data.removeprefix(b"\xef\xbb\xbf")
    head, sep, body = data.partition(b"\n")
    ncols = None
    first = 1
    if head[:1].isalpha():
        if not head.isascii():
            return None
        names = tuple(f.strip().lower() for f in head.decode().rstrip("\r").split(","))
        if names not in (LINK_COLUMNS[:4], LINK_COLUMNS):
            return None
        ncols, first = len(names), 2
    else:
        body = data
    if not body.strip() or body.translate(None, _PLAIN) \
            or body.count(b"\r") != body.count(b"\r\n"):
        return None
    body = body.replace(b"\r\n", b"\n")
    body = body[:-1] if body.endswith(b"\n") else body
    raw = np.frombuffer(body, dtype=np.uint8)
    ends = np.concatenate([np.flatnonzero(raw == 10), [raw.size]])
    if np.diff(ends, prepend=-1).max() > MAX_LINE_BYTES or (np.diff(ends, prepend=-1) < 2).any():
        return None  # a long line or a blank one
    commas = np.diff(np.searchsorted(np.flatnonzero(raw == 44), ends), prepend=0)
    if ncols is None:
        ncols = int(commas[0]) + 1
    if ncols not in (4, 5) or (commas != ncols - 1).any():
        return None
    fields = np.array(body.replace(b"\n", b",").split(b",")).reshape(-1, ncols)
    if not np.char.isdigit(fields[:, :4]).all():  # "+1", "1e3", "-1": the row reader's
        return None
    try:
        a = fields[:, :4].astype(np.int64)
        quality = fields[:, 4].astype(np.float64) if ncols == 5 else None
    except (ValueError, OverflowError):
        return None
    if (a < 0).any() or (a > MAX_ID).any() or (a[:, 0] == a[:, 2]).any() \
            or (quality is not None and not np.isfinite(quality).all()):
        return None
    ci, fi, cj, fj = _normalised(a).T
    if any(_first_duplicate(*cols) is not None for cols, _ in _one_to_one(ci, fi, cj, fj)):
        return None
    return LinksFile(Links(ci, fi, cj, fj, quality), first + np.arange(len(a), dtype=np.int64),
                     ncols == 5)


def _normalised(a: np.ndarray) -> np.ndarray:
    """Rows ``cam_i,feat_i,cam_j,feat_j`` with ``cam_i < cam_j`` (ends swapped where not)."""
    a = a.copy()
    swap = a[:, 0] > a[:, 2]
    a[swap] = a[swap][:, [2, 3, 0, 1]]
    return a


def _one_to_one(ci, fi, cj, fj) -> tuple:
    """The columns no two links may share, each with the message of a pair that does."""
    return (
        ((ci, fi, cj, fj), "duplicate link (the same link twice)"),
        ((ci, fi, cj), "not one-to-one: feature {0},{1} is linked twice to camera {2}"),
        ((cj, fj, ci), "not one-to-one: feature {2},{3} is linked twice to camera {0}"),
    )


def read_links_csv(path: str | os.PathLike) -> LinksFile:
    """Read and validate a user links file.

    Parameters
    ----------
    path : path to a CSV with rows ``cam_i,feat_i,cam_j,feat_j[,quality]``, or a run-output
        ``links.csv`` (header ``cam_i,feat_i,cam_j,feat_j,status,reason,round,truth``, and
        ``,quality`` where ``resolve`` kept its input's), whose status, reason and round are
        returned too

    Returns
    -------
    LinksFile

    Raises
    ------
    InputError
        Missing file; a row with the wrong number of columns (4 or 5, the same in every row), a
        non-integer or negative id, a non-finite quality, a self-link, a duplicate link (among
        all rows of a run-output links.csv, whatever their status) or one that breaks
        one-to-one-ness (among the kept rows of a run-output links.csv) — naming the row number
        and its content.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "links.csv"
    >>> _ = p.write_text("cam_i,feat_i,cam_j,feat_j\\n1,5,0,2\\n")
    >>> lf = read_links_csv(p)
    >>> (lf.links.cam_i.tolist(), lf.links.feat_i.tolist(), lf.links.cam_j.tolist())
    ([0], [2], [1])
    """
    path = Path(path)
    plain = _read_plain(path)
    if plain is not None:
        return plain
    lines, raws, vals, quals = [], [], [], []
    run_cols: list[tuple[str, str, int]] = []
    ncols = None
    run_width = None  # the columns of a run-output links.csv: 8, or 9 with quality
    first = True
    for lineno, fields, raw in _rows(path):
        if first:
            first = False
            header = tuple(f.lower() for f in fields)
            if header in (RUN_LINK_COLUMNS, RUN_LINK_QUALITY_COLUMNS):
                # a run-output links.csv, e.g. resolve's own: read as a links file of 4
                # columns, or 5 with its quality
                run_width = len(header)
                ncols = 5 if header == RUN_LINK_QUALITY_COLUMNS else 4
                continue
            if any(f.lower() in LINK_COLUMNS for f in fields):  # a header, in some order
                if tuple(f.lower() for f in fields) not in (LINK_COLUMNS[:4], LINK_COLUMNS):
                    raise InputError(f"{path}:{lineno}: header {raw!r} must be "
                                     f"'cam_i,feat_i,cam_j,feat_j' or with ',quality'")
                ncols = len(fields)
                continue
        if run_width is not None:
            if len(fields) != run_width:
                names = RUN_LINK_QUALITY_COLUMNS[:run_width]
                raise InputError(f"{path}:{lineno}: {raw!r} has {len(fields)} columns; the "
                                 f"header names {run_width} ({','.join(names)})")
            if fields[4] not in ("kept", "deleted"):
                raise InputError(f"{path}:{lineno}: {raw!r}: status {fields[4]!r} is not "
                                 "'kept' or 'deleted'")
            rnd = -1 if fields[6] == "" else _int_field(path, lineno, raw, "round", fields[6])
            if fields[7] not in ("", "0", "1"):
                raise InputError(f"{path}:{lineno}: {raw!r}: truth {fields[7]!r} is not 1 "
                                 "(good), 0 (spurious) or empty")
            run_cols.append((fields[4], fields[5], rnd, -1 if fields[7] == "" else
                             int(fields[7])))
            fields = fields[:4] + fields[8:]  # the ids, and the quality if the file has it
        elif len(fields) not in (4, 5):
            sep = next((f" (columns are separated by commas, not {name})"
                        for c, name in (("\t", "tabs"), (";", "semicolons"), (" ", "spaces"))
                        if len(fields) == 1 and c in raw.strip()), "")
            raise InputError(f"{path}:{lineno}: {raw!r} has {len(fields)} "
                             f"column{'s' if len(fields) != 1 else ''}; expected 4 "
                             f"(cam_i,feat_i,cam_j,feat_j) or 5 (with quality){sep}")
        if ncols is None:
            ncols = len(fields)
        elif len(fields) != ncols and not run_cols:
            raise InputError(f"{path}:{lineno}: {raw!r} has {len(fields)} columns but the file "
                             f"started with {ncols}; give quality on every row or on none")
        ids = [_int_field(path, lineno, raw, name, v)
               for name, v in zip(LINK_COLUMNS[:4], fields[:4], strict=True)]
        if ids[0] == ids[2]:
            raise InputError(f"{path}:{lineno}: {raw!r}: self-link within camera {ids[0]}; "
                             "a link must join two different cameras")
        if ncols == 5:
            if not NUMBER.fullmatch(fields[4]) and fields[4].lower() not in (
                    "nan", "inf", "-inf", "+inf", "infinity", "-infinity", "+infinity"):
                raise InputError(f"{path}:{lineno}: {raw!r}: quality {fields[4]!r} is not a "
                                 "number written in digits 0-9 (e.g. 0.75 or 1e-3)")
            q = float(fields[4])
            if not math.isfinite(q):
                raise InputError(f"{path}:{lineno}: {raw!r}: quality {fields[4]!r} is not a "
                                 "finite number")
            quals.append(q)
        lines.append(lineno)
        raws.append(raw)
        vals.append(ids)

    a = _normalised(np.asarray(vals, dtype=np.int64).reshape(-1, 4))
    ci, fi, cj, fj = a.T
    # the rows to make consistent: in a run-output links.csv only the kept ones (its deleted
    # rows stay deleted; clean-db and clean-h5 delete rows that break one-to-one-ness there)
    rows = np.flatnonzero([st == "kept" for st, *_ in run_cols]) if run_cols \
        else np.arange(len(a))
    # but every row of it once: a run lists each of its links once, kept or deleted, so a
    # link twice (say once deleted, once kept) is a damaged file, which would be resolved
    # with both rows and written twice
    dup = _first_duplicate(ci, fi, cj, fj) if run_cols else None
    if dup is not None:
        k0, k1 = dup
        raise InputError(f"{path}:{lines[k1]}: {raws[k1]!r}: duplicate link (the same link as "
                         f"row {lines[k0]}: {raws[k0]!r}); a run-output links.csv lists every "
                         "link once, kept or deleted: the file is damaged; remove one of the "
                         "two rows or give the run's own links.csv")
    for cols, what in _one_to_one(*a[rows].T):
        dup = _first_duplicate(*cols)
        if dup is not None:
            k0, k1 = rows[dup[0]], rows[dup[1]]
            msg = what.format(*a[k1].tolist())
            raise InputError(f"{path}:{lines[k1]}: {raws[k1]!r}: {msg} (also row {lines[k0]}: "
                             f"{raws[k0]!r}); matching must give a one-to-one association per "
                             "camera pair")
    quality = np.asarray(quals, dtype=np.float64) if ncols == 5 else None
    out = LinksFile(Links(ci, fi, cj, fj, quality), np.asarray(lines, dtype=np.int64), ncols == 5)
    if run_width is not None:
        st, rs, rd, tr = zip(*run_cols, strict=True) if run_cols else ((), (), (), ())
        out.status = np.asarray(st, dtype=object).astype(str)
        out.reason = np.asarray(rs, dtype=object).astype(str)
        truth = np.asarray(tr, dtype=np.int8)
        out.truth = truth if (truth >= 0).any() else None
        out.round = np.asarray(rd, dtype=np.int64)
    return out


def features_per_camera_for(links: Links, n_cameras: int | None = None) -> np.ndarray:
    """Smallest feature counts that hold every id: ``max feat + 1`` per camera, ``(n,)``.

    ``n_cameras`` (e.g. from a comm graph) may add cameras without links.
    """
    n = int(max(links.cam_j.max(initial=-1), links.cam_i.max(initial=-1))) + 1
    if n_cameras is not None:
        n = max(n, int(n_cameras))
    m = np.zeros(n, dtype=np.int64)
    np.maximum.at(m, links.cam_i, links.feat_i + 1)
    np.maximum.at(m, links.cam_j, links.feat_j + 1)
    return m


def write_links_csv(path: str | os.PathLike, ledger: LinkLedger, quality: bool = False) -> Path:
    """Write the run-output ``links.csv`` of ``ledger`` atomically (temp file, then
    ``os.replace``).

    Columns ``cam_i,feat_i,cam_j,feat_j,status,reason,round,truth``: a negative round is
    written empty, and so is an unknown truth (``-1``, or ``ledger.truth`` is ``None``). With
    ``quality``, a last column ``quality``: each link's ``ledger.links.quality``, written so
    that it reads back as the same float64 (``resolve`` keeps the quality of its input so).

    Returns
    -------
    Path — the file written
    """
    path = Path(path)
    ledger.check()
    links = ledger.links
    round_ = ledger.round
    truth = np.full(len(links), -1, dtype=np.int64) if ledger.truth is None \
        else ledger.truth.astype(np.int64)
    round_s = np.where(round_ >= 0, round_.astype(str), "")
    truth_s = np.where(truth >= 0, truth.astype(str), "")
    columns = [links.cam_i.tolist(), links.feat_i.tolist(), links.cam_j.tolist(),
               links.feat_j.tolist(), ledger.status.astype(str).tolist(),
               ledger.reason.astype(str).tolist(), round_s.tolist(), truth_s.tolist()]
    if quality:  # repr: the shortest text that reads back as the same float
        columns.append([repr(q) for q in np.asarray(links.quality, np.float64).tolist()])
    with atomic_file(path, newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(RUN_LINK_QUALITY_COLUMNS if quality else RUN_LINK_COLUMNS)
        w.writerows(zip(*columns, strict=True))
    return path


def read_run_links_csv(path: str | os.PathLike) -> LinkLedger:
    """Read a run-output ``links.csv`` back as a :class:`~pipeline.types.LinkLedger`.

    ``iteration`` and ``case`` are not stored in the file and read back as ``-1`` and ``''``;
    ``truth`` and ``round`` read back as ``-1`` where empty; blank lines are skipped. A last
    column ``quality`` (``resolve`` of a links file with one) is read into the links'
    quality; without it the quality is 1.

    Raises
    ------
    InputError
        Not the run header; a row with another number of columns than the header, an id or
        round that is not a whole number >= 0, a truth other than 1, 0 or empty, a status
        other than ``kept`` or ``deleted``, a quality that is not a finite number (naming the
        file, the line and the value).
    """
    from pipeline.inputs.csvfields import csv_row, text_lines

    path = Path(path)
    rows = [(n, line, csv_row(line, f"{path}:{n}")) for n, line in text_lines(path, "links file")
            if line.strip()]
    header = tuple(rows[0][2]) if rows else ()
    if header not in (RUN_LINK_COLUMNS, RUN_LINK_QUALITY_COLUMNS):
        raise InputError(f"{path}: not a run links.csv (header must be {','.join(RUN_LINK_COLUMNS)}"
                         ", with ,quality last or without)")
    body = []
    quals = []
    for lineno, raw, fields in rows[1:]:
        if len(fields) != len(header):
            raise InputError(f"{path}:{lineno}: {raw!r} has {len(fields)} columns; the header "
                             f"names {len(header)} ({','.join(header)})")
        if len(header) > len(RUN_LINK_COLUMNS):
            q = fields[8]
            if not NUMBER.fullmatch(q) or not math.isfinite(float(q)):
                raise InputError(f"{path}:{lineno}: {raw!r}: quality {q!r} is not a finite "
                                 "number written in digits 0-9 (e.g. 0.75 or 1e-3)")
            quals.append(float(q))
        ids = [_int_field(path, lineno, raw, name, v)
               for name, v in zip(RUN_LINK_COLUMNS[:4], fields[:4], strict=True)]
        rnd = "" if fields[6] == "" else str(_int_field(path, lineno, raw, "round", fields[6]))
        if fields[7] not in ("", "0", "1"):
            raise InputError(f"{path}:{lineno}: {raw!r}: truth {fields[7]!r} is not 1 (good), "
                             "0 (spurious) or empty")
        body.append([*map(str, ids), fields[4], fields[5], rnd, fields[7]])
    col = {name: [r[k] for r in body] for k, name in enumerate(RUN_LINK_COLUMNS)}

    def ints(vals):
        return np.array([int(v) if v != "" else -1 for v in vals], dtype=np.int64)

    links = Links(ints(col["cam_i"]), ints(col["feat_i"]), ints(col["cam_j"]),
                  ints(col["feat_j"]),
                  np.asarray(quals, np.float64) if len(header) > len(RUN_LINK_COLUMNS) else None)
    try:
        return LinkLedger(links, np.array(col["status"], dtype=str),
                          np.array(col["reason"], dtype=str), ints(col["round"]),
                          np.full(len(links), -1, dtype=np.int64),
                          np.full(len(links), "", dtype=object),
                          ints(col["truth"]))
    except ValueError as exc:
        raise InputError(f"{path}: {exc}") from None
