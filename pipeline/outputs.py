"""Where a command may write: the one guard every output path goes through.

Rules (each broken rule is an :class:`~pipeline.errors.InputError` naming the path, the flag
and what to do, raised before any work is done):

- An output never resolves (after following symbolic links, or as a hard link) to an input
  of the same command, nor to another output of it.
- An output file is a regular file or a new name: a folder, a device (``/dev/null``), a FIFO,
  a socket or a symbolic link is never replaced or written through.
- An existing output file is replaced only with ``--overwrite``.
- A run folder (``--out`` of ``run-formation`` / ``run-images``) is replaced as a whole, so it
  must be a new name, an empty folder or a folder that carries the run marker
  (:data:`RUN_MARKER`, written into every run folder); it may not be a symbolic link, ``/``,
  the current folder or one of its parents, nor an input or a folder holding an input.
- The folder an output goes into must be writable.

Reading: :func:`require_input_file` says "is a folder" or "no such file" for a bad input file.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Iterable
from pathlib import Path

from pipeline.errors import InputError

__all__ = ["RUN_MARKER", "check_output_files", "check_run_folder", "refuse_unsafe_target",
           "require_input_file"]

#: File written into every run folder; only a folder holding it may be replaced by a new run.
RUN_MARKER = ".formation-match-run"

Named = Iterable[tuple[str, "str | os.PathLike | None"]]


def _real(path) -> Path:
    return Path(os.path.realpath(os.fspath(path)))


def _same(a, b) -> bool:
    """``a`` and ``b`` are the same file system entry (symlinks followed, hard links too)."""
    if _real(a) == _real(b):
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def require_input_file(path, what: str) -> Path:
    """``Path(path)`` if it names a readable regular file; else an InputError.

    Parameters
    ----------
    path : the file a flag named
    what : how to call it in the message, e.g. ``"--links"`` or ``"links file"``
    """
    p = Path(path)
    if p.is_dir():
        raise InputError(f"{what} {str(p)!r} is a folder, not a file; give the file itself")
    if not p.exists():
        raise InputError(f"{what} {str(p)!r}: no such file")
    if not p.is_file():
        raise InputError(f"{what} {str(p)!r} is not a regular file (a device, FIFO or socket); "
                         "give a file")
    return p


def _check_writable_folder(path: Path, flag: str) -> None:
    """The nearest existing ancestor of ``path`` must be a folder we may write in."""
    parent = Path(os.path.abspath(path)).parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        raise InputError(f"{flag} {str(path)!r}: {str(parent)!r} is a file, not a folder; "
                         "choose another place")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise InputError(f"{flag} {str(path)!r}: cannot write in {str(parent)!r} (read-only or "
                         "no permission); choose a folder you can write in")


def refuse_unsafe_target(path, flag: str = "output") -> None:
    """InputError if ``path`` is a symbolic link or an existing non-regular file.

    Writes replace their target by a rename; a rename over ``/dev/null``, a FIFO or a symbolic
    link would replace that special entry, so it is refused.
    """
    p = Path(path)
    if p.is_symlink():
        raise InputError(f"{flag} {str(p)!r} is a symbolic link (to {os.path.realpath(p)!r}); "
                         "outputs never replace or write through a link: give a plain file name")
    try:
        mode = p.lstat().st_mode
    except FileNotFoundError:
        return
    if stat.S_ISDIR(mode):
        raise InputError(f"{flag} {str(p)!r} is a folder; give the name of a file to write, "
                         f"e.g. {str(p / 'out')!r}")
    if not stat.S_ISREG(mode):
        raise InputError(f"{flag} {str(p)!r} is not a regular file (a device, FIFO or socket); "
                         "it is never replaced: give the name of a file to write")


def check_output_files(outputs: Named, inputs: Named = (), overwrite: bool = False) -> None:
    """Check the output files of one command (see the module rules).

    Parameters
    ----------
    outputs : ``(flag, path)`` pairs, e.g. ``[("--out", "o.csv"), ("--report", None)]``;
        ``None`` paths are skipped
    inputs : ``(flag, path)`` pairs of the files (or folders) the command reads
    overwrite : replace existing regular files (the ``--overwrite`` flag)

    Raises
    ------
    InputError
        The first broken rule, naming the flag and the path.
    """
    outs = [(f, Path(p)) for f, p in outputs if p is not None]
    ins = [(f, Path(p)) for f, p in inputs if p is not None]
    for flag, p in outs:
        if not str(p) or p.name in ("", ".", ".."):
            raise InputError(f"{flag} {str(p)!r}: give the name of a file to write")
        refuse_unsafe_target(p, flag)
        for in_flag, q in ins:
            if q.exists() and _same(p, q):
                raise InputError(f"{flag} {str(p)!r} is the input file given as {in_flag} "
                                 f"({str(q)!r}); inputs are never modified: choose another "
                                 "output name")
        if p.exists() and not overwrite:
            raise InputError(f"{flag} {str(p)!r} already exists; pass --overwrite to replace it, "
                             "or choose a new name")
        _check_writable_folder(p, flag)
    for k, (flag, p) in enumerate(outs):
        for flag2, q in outs[k + 1:]:
            if _real(p) == _real(q):
                raise InputError(f"{flag} and {flag2} name the same file {str(p)!r}; give each "
                                 "output its own name")


def check_run_folder(out, inputs: Named = (), flag: str = "--out") -> Path:
    """Check that the run folder ``out`` may be (re)placed by a new run; return it as a Path.

    Raises
    ------
    InputError
        ``out`` is a symbolic link, a file, ``/``, the current folder or one of its parents,
        an input or a folder holding an input, or an existing non-empty folder without the
        :data:`RUN_MARKER` of a previous run.
    """
    p = Path(out)
    if not str(out) or p.is_symlink():
        what = "is a symbolic link" if str(out) else "is empty"
        raise InputError(f"{flag} {str(out)!r} {what}; give the name of a run folder")
    real = _real(p)
    cwd = _real(Path.cwd())
    if real == Path(real.anchor) or real == cwd or real in cwd.parents:
        raise InputError(f"{flag} {str(out)!r} is {'/' if real == Path(real.anchor) else 'the current folder or one of its parents'}; "
                         "a run folder is replaced as a whole: give a new folder name, e.g. "
                         "runs/NAME")
    for in_flag, q in inputs:
        if q is None:
            continue
        rq = _real(q)
        if rq == real or real in rq.parents:
            raise InputError(f"{flag} {str(out)!r} holds the input {in_flag} {str(q)!r}; a run "
                             "folder is replaced as a whole, which would delete it: choose "
                             "another --out")
    if p.exists():
        if not p.is_dir():
            raise InputError(f"{flag} {str(out)!r} is a file; a run is written as a folder: "
                             "choose a folder name")
        if not (p / RUN_MARKER).is_file():
            try:
                empty = next(p.iterdir(), None) is None
            except OSError as exc:
                raise InputError(f"{flag} {str(out)!r}: cannot list it ({exc.strerror})") from None
            if not empty:
                raise InputError(
                    f"{flag} {str(out)!r} exists and is not a formation-match run folder (no "
                    f"{RUN_MARKER} file in it); it is never replaced: choose another --out, or "
                    "move it away yourself")
    _check_writable_folder(p, flag)
    return p
