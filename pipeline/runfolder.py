"""Atomic run folders (docs/DESIGN.md "Run outputs — a contract").

A run writes into a staging folder ``.NAME.tmp-*`` beside ``NAME``; only when everything is
written is it put in place. Guarantees:

- **Only our own run folders are replaced.** Every run folder carries the marker file
  :data:`~pipeline.outputs.RUN_MARKER`; :func:`~pipeline.outputs.check_run_folder` refuses any
  other existing non-empty folder, a file, a symbolic link, ``/``, the current folder or its
  parents, and a folder holding an input.
- **One writer per run folder.** A run holds an exclusive ``fcntl.flock`` on ``.NAME.lock``
  beside the folder (holding its pid) from :func:`claim_run_folder` (the start of a command)
  until its folder is in place. A second run into the same ``--out`` does not wait: it stops
  at once with an InputError naming the pid that holds the folder.
- **Either the old or the new run is in place at every instant.** The staging folder and the
  old run are swapped in one ``renameat2(RENAME_EXCHANGE)`` system call (Linux); where the file
  system lacks it, the old run is renamed ``.NAME.old-PID`` and the new one renamed into place
  (two steps). A run killed between those two steps leaves ``NAME`` missing and
  ``.NAME.old-PID`` present: the next run into ``NAME`` restores it when it takes the lock.
- **No leftovers.** Under the lock no other run can be staging ``NAME``, so every
  ``.NAME.tmp-*`` and ``.NAME.old-*`` found then belongs to a dead run and is removed.
  The lock file is removed by its holder while still locked; a run that locked a file
  already removed retries on the new one.
"""

from __future__ import annotations

import ctypes
import errno
import fcntl
import json
import os
import shutil
import sys
import tempfile
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from pipeline.errors import InputError
from pipeline.outputs import RUN_MARKER, check_run_folder, refuse_unsafe_target

__all__ = ["atomic_file", "atomic_run_folder", "claim_run_folder", "write_json_atomic"]


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _publish_mode(path: str | os.PathLike, directory: bool) -> None:
    """Give a temp file/folder the mode a plain ``open``/``mkdir`` would have given it
    (``mkstemp``/``mkdtemp`` create them private, 0600/0700)."""
    os.chmod(path, (0o777 if directory else 0o666) & ~_umask())


def _json_default(obj):
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.floating):
        return float(obj)
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serializable: {type(obj).__name__}")


@contextmanager
def atomic_file(path: str | os.PathLike, mode: str = "w", newline: str | None = None):
    """Open a temporary file beside ``path``; on success it replaces ``path`` in one rename.

    On any error the temporary file is removed and ``path`` is left as it was. A ``path``
    that is a symbolic link, a folder or a special file (``/dev/null``, a FIFO) is refused
    (InputError) rather than replaced.
    """
    path = Path(path)
    refuse_unsafe_target(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, mode, newline=newline) as f:
            yield f
        _publish_mode(tmp, directory=False)
        refuse_unsafe_target(path)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def write_json_atomic(path: str | os.PathLike, data) -> Path:
    """Write ``data`` as indented JSON to ``path`` atomically (see :func:`atomic_file`)."""
    with atomic_file(path) as f:
        json.dump(data, f, indent=2, default=_json_default)
        f.write("\n")
    return Path(path)


# ------------------------------------------------------------------------------ the lock

#: run folders whose lock this process holds: real path -> [fd, depth]
_held: dict[str, list[int]] = {}


def _key(out: Path) -> str:
    return os.path.join(os.path.realpath(out.parent), out.name)


def _leftovers(out: Path, kind: str) -> list[Path]:
    prefix = f".{out.name}.{kind}-"
    try:
        return sorted(p for p in out.parent.iterdir() if p.name.startswith(prefix))
    except FileNotFoundError:
        return []


def _recover(out: Path) -> None:
    """Under the lock: restore a run lost between the two renames, drop dead leftovers."""
    olds = _leftovers(out, "old")
    if olds and not os.path.lexists(out):
        newest = max(olds, key=lambda p: p.stat().st_mtime)
        os.rename(newest, out)
        olds.remove(newest)
        print(f"note: restored the previous run {out} from {newest.name} (a run was stopped "
              "while putting its folder in place)", file=sys.stderr)
    for p in olds + _leftovers(out, "tmp"):
        shutil.rmtree(p, ignore_errors=True)


@contextmanager
def claim_run_folder(out: str | os.PathLike, inputs=(), flag: str = "--out"):
    """Check ``out`` (:func:`pipeline.outputs.check_run_folder`) and hold its lock.

    Commands enter it before doing any work, so a bad or busy ``--out`` is refused at once;
    :func:`atomic_run_folder` inside it reuses the lock. Re-entrant within one process.

    Raises
    ------
    InputError
        ``out`` may not be replaced (see :mod:`pipeline.outputs`), or another live run holds
        it (the message names its pid).
    """
    out = Path(out)
    key = _key(out)
    if key in _held:
        _held[key][1] += 1
        try:
            yield out
        finally:
            _held[key][1] -= 1
        return
    check_run_folder(out, inputs, flag)
    out.parent.mkdir(parents=True, exist_ok=True)
    lock = out.parent / f".{out.name}.lock"
    fd = _lock(lock, out, flag)
    try:
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        _held[key] = [fd, 1]
        try:
            _recover(out)
            check_run_folder(out, inputs, flag)  # the restored folder, if any, is checked too
            yield out
        finally:
            del _held[key]
            os.unlink(lock)  # while still locked: see _lock
    finally:
        os.close(fd)  # releases the flock


def _lock(lock: Path, out: Path, flag: str) -> int:
    """Open and flock ``lock``; the fd. The holder unlinks the file before unlocking, so a
    lock taken on a file that is no longer at ``lock`` is stale: drop it and try again."""
    while True:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            pid = os.pread(fd, 32, 0).decode(errors="replace").strip() or "?"
            os.close(fd)
            raise InputError(f"{flag} {str(out)!r} is being written by another run (pid {pid}); "
                             "wait for it to finish or choose another --out") from None
        try:
            same = os.stat(lock).st_ino == os.fstat(fd).st_ino
        except FileNotFoundError:
            same = False
        if same:
            return fd
        os.close(fd)


# ------------------------------------------------------------------------------ the swap

_RENAME_EXCHANGE = 2
_AT_FDCWD = -100


def _renameat2():
    try:
        fn = ctypes.CDLL(None, use_errno=True).renameat2
    except (AttributeError, OSError):
        return None
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    fn.restype = ctypes.c_int
    return fn


def _exchange(a: Path, b: Path) -> bool:
    """Swap ``a`` and ``b`` in one system call; False where the system cannot."""
    fn = _renameat2()
    if fn is None:
        return False
    if fn(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.ENOSYS, errno.EINVAL, errno.ENOTSUP, errno.EPERM):
        return False
    raise OSError(err, os.strerror(err), str(b))


def _put_in_place(staged: Path, out: Path) -> None:
    """Replace ``out`` by ``staged`` so that one of the two complete runs is always at ``out``."""
    if not os.path.lexists(out):
        os.rename(staged, out)
        return
    if _exchange(staged, out):
        shutil.rmtree(staged, ignore_errors=True)  # now holds the old run
        return
    old = out.parent / f".{out.name}.old-{os.getpid()}"
    os.rename(out, old)
    os.rename(staged, out)  # a kill before this line is repaired by _recover
    shutil.rmtree(old, ignore_errors=True)


@contextmanager
def atomic_run_folder(out: str | os.PathLike, inputs=()):
    """Yield a staging folder; on success it is put in place of ``out`` atomically.

    The staging folder gets the run marker. Holds (or reuses) the lock of
    :func:`claim_run_folder`. On any error the staging folder is removed and ``out`` is left
    as it was.

    Example
    -------
    >>> import pathlib, tempfile
    >>> out = pathlib.Path(tempfile.mkdtemp()) / "demo"
    >>> with atomic_run_folder(out) as tmp:
    ...     _ = (tmp / "report.json").write_text("{}")
    >>> sorted(p.name for p in out.parent.iterdir())  # no temporary folder left
    ['demo']
    >>> sorted(p.name for p in out.iterdir())
    ['.formation-match-run', 'report.json']
    """
    out = Path(out)
    with claim_run_folder(out, inputs):
        tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.tmp-", dir=out.parent))
        try:
            yield tmp
            (tmp / RUN_MARKER).write_text("formation-match run folder: a new run may replace "
                                          "this folder\n")
            _publish_mode(tmp, directory=True)
            check_run_folder(out, inputs)  # nothing foreign was put there meanwhile
            _put_in_place(tmp, out)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
