"""Atomic run folders (docs/DESIGN.md "Run outputs — a contract").

A run writes into a temporary sibling folder; only when everything is written is it renamed
over ``runs/<name>/``. A run that fails midway leaves the previous run of that name intact.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path

import numpy as np

__all__ = ["atomic_file", "atomic_run_folder", "write_json_atomic"]


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

    On any error the temporary file is removed and ``path`` is left as it was.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, mode, newline=newline) as f:
            yield f
        _publish_mode(tmp, directory=False)
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


@contextmanager
def atomic_run_folder(out: str | os.PathLike):
    """Yield a temporary folder; on success it replaces ``out`` in one rename.

    The previous ``out`` (if any) is moved aside first and removed only after the new folder is
    in place, so at every instant either the old or the new run is complete on disk.

    Example
    -------
    >>> import pathlib, tempfile
    >>> out = pathlib.Path(tempfile.mkdtemp()) / "demo"
    >>> with atomic_run_folder(out) as tmp:
    ...     _ = (tmp / "report.json").write_text("{}")
    >>> sorted(p.name for p in out.parent.iterdir())  # no temporary folder left
    ['demo']
    >>> [p.name for p in out.iterdir()]
    ['report.json']
    """
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.tmp-", dir=out.parent))
    try:
        yield tmp
        _publish_mode(tmp, directory=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    old = None
    if out.exists():
        old = Path(tempfile.mkdtemp(prefix=f".{out.name}.old-", dir=out.parent))
        os.rmdir(old)
        os.replace(out, old)
    try:
        os.replace(tmp, out)
    except BaseException:
        if old is not None:
            os.replace(old, out)
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
