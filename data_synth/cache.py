"""On-disk cache of rendered views, so that a formation is rendered once per machine.

Rendering (scene textures, then every camera) is deterministic: the same seed, image size,
number of robots and rendering code give the same pixels. The views of a formation do not
depend on its communication graph (formations ``a``–``d`` with one seed share their images),
so an entry holds the views of one ``(seed, size, robots)`` and the graph is rebuilt from its
rule. The key also holds a digest of the ``data_synth`` source files and the NumPy and OpenCV
versions, so that changed rendering code never reads old pixels.

Where: ``$FORMATION_MATCH_CACHE`` if set, else ``$XDG_CACHE_HOME/formation-match``, else
``~/.cache/formation-match``; off when there is no home folder (``HOME`` empty, not an existing
folder, or unset with no password entry). ``FORMATION_MATCH_CACHE=off`` (or ``0``, ``no``,
``false``) turns the cache off. One uncompressed ``.npz`` per entry (~13 MB at 640x480 with 6 robots),
written to a temporary file and renamed (concurrent runs never see half a file). An entry that
cannot be read or does not hold what its name says is ignored and written again. Each camera's
pixels and depth carry their CRC-32 (``crc``, stored after ``key``), so that one camera read
alone (:func:`load_view`, which does not read the whole archive member and so does not meet
the zip's own CRC) is checked too: a damaged entry gives no view, never a wrong one.

The folder is kept under a size cap, ``$FORMATION_MATCH_CACHE_MAX_MB`` (default 1024 MB): each
write removes the least recently used entries (a hit marks its entry used) until the folder
fits, never the entry just written, so entries of older code versions, which are never used
again, go first. Temporary files left by killed runs are removed after an hour.

The folder may be one of the user's (``FORMATION_MATCH_CACHE=~/data``): only files this
module wrote are ever removed, those whose name is an entry's (``views-…-<digest>.npz``, or
``.views-….tmp-*.npz`` while written) and whose first stored array, ``key`` (written first),
holds that same name. Any other file, and a symbolic link, is left alone.
"""

from __future__ import annotations

import functools
import hashlib
import io
import os
import re
import stat
import tempfile
import tokenize
import zipfile
import zlib
from pathlib import Path

import cv2
import numpy as np

__all__ = ["ENV", "MAX_MB_ENV", "DEFAULT_MAX_MB", "cache_dir", "code_version", "load_views",
           "load_view", "save_views", "entry_path", "prune", "max_bytes"]

ENV = "FORMATION_MATCH_CACHE"
"""Environment variable: the cache folder, or ``off`` to disable the cache."""

_OFF = {"off", "0", "no", "false", "none"}

MAX_MB_ENV = "FORMATION_MATCH_CACHE_MAX_MB"
"""Environment variable: the cache folder's size cap in MB (see the module docstring)."""

DEFAULT_MAX_MB = 1024

#: a temporary file older than this (seconds) is a leftover of a killed run
_STALE_TMP_S = 3600.0


def cache_dir() -> Path | None:
    """The cache folder, or ``None`` when the cache is turned off (see the module docstring)."""
    value = os.environ.get(ENV)
    if value is not None:
        if value.strip().lower() in _OFF or not value.strip():
            return None
        return Path(value).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or ""
    # XDG: a relative XDG_CACHE_HOME is invalid and is ignored
    if base and Path(base).is_absolute():
        return Path(base) / "formation-match"
    home = os.environ.get("HOME")
    if home is None:
        try:
            home = str(Path.home())  # the password database's
        except RuntimeError:  # no entry for this user either
            return None
    if not home or not Path(home).is_absolute() or not Path(home).is_dir():
        return None  # no home to keep it in: never a /.cache, nor a home made for the cache
    return Path(home) / ".cache" / "formation-match"


@functools.cache
def code_version() -> str:
    """Digest of the ``data_synth`` sources and the NumPy and OpenCV versions, 16 hex digits."""
    h = hashlib.blake2b(digest_size=8)
    for path in sorted(Path(__file__).resolve().parent.glob("*.py")):
        h.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    h.update(f"numpy {np.__version__} opencv {cv2.__version__}".encode())
    return h.hexdigest()


def max_bytes() -> int:
    """The size cap in bytes from ``$FORMATION_MATCH_CACHE_MAX_MB``; the default when it is
    unset or not a number >= 0 (the cache is an optimisation: a bad value is never fatal)."""
    value = os.environ.get(MAX_MB_ENV, "")
    try:
        mb = float(value)
    except ValueError:
        mb = float(DEFAULT_MAX_MB)
    if not mb >= 0 or mb == float("inf"):
        mb = float(DEFAULT_MAX_MB)
    return int(mb * 1024 * 1024)


def _mark_used(path: Path) -> None:
    try:
        os.utime(path)
    except OSError:
        pass


#: what reading a damaged entry raises: besides OSError, ValueError (numpy) and the zip's own
#: errors, a changed byte in a zip header gives NotImplementedError (an unknown compression
#: method or version) or RuntimeError (an "encrypted" member), and one in an array's header
#: tokenize's TokenError or SyntaxError (numpy parses it as a Python literal) or MemoryError
#: (a shape no memory holds)
_UNREADABLE = (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, NotImplementedError,
               RuntimeError, SyntaxError, tokenize.TokenError, MemoryError)

#: an entry's name, and a temporary file's while it is written (the key in group 1)
_ENTRY_NAME = re.compile(r"(views-seed\d+-\d+x\d+-n\d+-[0-9a-f]{16})\.npz")
_TMP_NAME = re.compile(r"\.(views-seed\d+-\d+x\d+-n\d+-[0-9a-f]{16})\.tmp-[^/]+\.npz")


def _stored_key(path: Path) -> str | None:
    """The ``key`` an entry file stores first (read from the zip's first local header, so a
    temporary file still being written has it too); None when ``path`` is a symbolic link,
    not a regular file, or does not start with that array."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
    except OSError:
        return None
    try:
        with os.fdopen(fd, "rb") as f:
            if not stat.S_ISREG(os.fstat(f.fileno()).st_mode):
                return None
            local = f.read(30)
            if len(local) != 30 or local[:4] != b"PK\x03\x04" or local[8:10] != b"\0\0":
                return None
            n, extra = int.from_bytes(local[26:28], "little"), int.from_bytes(local[28:30], "little")
            if f.read(n) != b"key.npy":
                return None
            f.seek(30 + n + extra)
            version = np.lib.format.read_magic(f)
            read_header = np.lib.format.read_array_header_1_0 if version == (1, 0) \
                else np.lib.format.read_array_header_2_0
            shape, _, dtype = read_header(f)
            if shape != () or dtype.kind != "U" or dtype.itemsize > 4096:
                return None
            data = f.read(dtype.itemsize)
            if len(data) != dtype.itemsize:
                return None
            return str(np.frombuffer(data, dtype=dtype)[0])
    except _UNREADABLE:
        return None


def prune(root: Path, keep: Path | None = None, limit: int | None = None) -> list[Path]:
    """Remove the least recently used entries of ``root`` until it holds at most ``limit``
    bytes (default :func:`max_bytes`), never ``keep``; remove temporary files older than an
    hour. Only files this module wrote are counted or removed (module notes). Returns the
    removed paths. Errors (a file gone meanwhile, no permission) are skipped.
    """
    import time

    limit = max_bytes() if limit is None else limit
    removed: list[Path] = []
    entries = []
    now = time.time()
    try:
        names = sorted(os.listdir(root))
    except OSError:
        return removed
    for name in names:
        path = root / name
        entry, tmp = _ENTRY_NAME.fullmatch(name), _TMP_NAME.fullmatch(name)
        if not (entry or tmp) or _stored_key(path) != (entry or tmp).group(1):
            continue
        try:
            st = path.lstat()
            if tmp:
                if now - st.st_mtime > _STALE_TMP_S:
                    path.unlink()
                    removed.append(path)
                continue
        except OSError:
            continue
        entries.append((st.st_mtime, st.st_size, path))
    total = sum(size for _, size, _ in entries)
    for _, size, path in sorted(entries):
        if total <= limit:
            break
        if keep is not None and path == keep:
            continue
        try:
            path.unlink()
        except OSError:
            continue
        total -= size
        removed.append(path)
    return removed


def _key(seed: int, size: tuple[int, int], n: int) -> str:
    return f"views-seed{seed}-{size[0]}x{size[1]}-n{n}-{code_version()}"


def entry_path(seed: int, size: tuple[int, int], n: int) -> Path | None:
    """Where the views of ``(seed, size, n robots)`` are cached; ``None`` with the cache off."""
    root = cache_dir()
    return None if root is None else root / f"{_key(seed, size, n)}.npz"


def load_views(seed: int, size: tuple[int, int], n: int) -> dict | None:
    """The cached arrays of ``(seed, size, n)``, or ``None`` (cache off, no entry, bad entry).

    Returns
    -------
    dict or None
        ``image`` (n, H, W, 3) uint8 RGB and ``depth`` (n, H, W) float32 of every camera
        (intrinsics and poses are cheap and always recomputed).
    """
    path = entry_path(seed, size, n)
    if path is None or not path.is_file():
        return None
    W, H = size
    shapes = {"image": ((n, H, W, 3), np.uint8), "depth": ((n, H, W), np.float32)}
    try:
        with np.load(path, allow_pickle=False) as z:
            if str(z["key"]) != _key(seed, size, n):
                return None
            out = {name: z[name] for name in shapes}
            crc = z["crc"]
    except _UNREADABLE:
        return None
    for name, (shape, dtype) in shapes.items():
        if out[name].shape != shape or out[name].dtype != dtype:
            return None
    if crc.shape != (n, 2) or crc.dtype != np.uint32:
        return None  # an entry without the cameras' CRCs: load_view could not check it
    _mark_used(path)
    return out


def _stored_array_slice(f, z: zipfile.ZipFile, name: str, shape: tuple, dtype, i: int):
    """Item ``i`` of the array ``name`` of an uncompressed ``.npz`` opened as ``z`` on ``f``,
    read at its offset in the file (the other items are not read); ``None`` if it does not
    hold an array of ``shape`` and ``dtype``."""
    info = z.getinfo(f"{name}.npy")
    if info.compress_type != zipfile.ZIP_STORED:
        return None
    f.seek(info.header_offset)
    local = f.read(30)  # the zip local file header: name and extra-field lengths at 26, 28
    if len(local) != 30 or local[:4] != b"PK\x03\x04":
        return None
    start = info.header_offset + 30 + int.from_bytes(local[26:28], "little") \
        + int.from_bytes(local[28:30], "little")
    f.seek(start)
    version = np.lib.format.read_magic(f)
    if version == (1, 0):
        got_shape, fortran, got_dtype = np.lib.format.read_array_header_1_0(f)
    else:
        got_shape, fortran, got_dtype = np.lib.format.read_array_header_2_0(f)
    if tuple(got_shape) != shape or got_dtype != np.dtype(dtype) or fortran:
        return None
    item = shape[1:]
    count = int(np.prod(item))
    f.seek(f.tell() + i * count * np.dtype(dtype).itemsize)
    out = np.fromfile(f, dtype=dtype, count=count)
    return out.reshape(item) if out.size == count else None


def load_view(seed: int, size: tuple[int, int], n: int, i: int) -> dict | None:
    """Camera ``i``'s arrays of the entry ``(seed, size, n)``, or ``None`` (as :func:`load_views`).

    Reads only that camera's pixels and depth from the file (a robot process needs its own
    view only).

    Returns
    -------
    dict or None
        ``image`` (H, W, 3) uint8 RGB and ``depth`` (H, W) float32.
    """
    path = entry_path(seed, size, n)
    if path is None or not path.is_file() or not 0 <= i < n:
        return None
    W, H = size
    shapes = {"image": ((n, H, W, 3), np.uint8), "depth": ((n, H, W), np.float32)}
    try:
        with open(path, "rb") as f, zipfile.ZipFile(f) as z:
            if str(np.load(io.BytesIO(z.read("key.npy")))) != _key(seed, size, n):
                return None
            crc = np.load(io.BytesIO(z.read("crc.npy")), allow_pickle=False)
            out = {name: _stored_array_slice(f, z, name, shape, dtype, i)
                   for name, (shape, dtype) in shapes.items()}
    except _UNREADABLE:
        return None
    if any(v is None for v in out.values()) or crc.shape != (n, 2) or crc.dtype != np.uint32:
        return None
    if [zlib.crc32(out[name]) for name in shapes] != crc[i].tolist():
        return None  # damaged on disk: the zip's CRC covers the whole member, not one camera
    _mark_used(path)
    return out


def _camera_crcs(arrays: dict) -> np.ndarray:
    """``(n, 2)`` uint32: the CRC-32 of each camera's ``image`` and ``depth`` bytes."""
    return np.array([[zlib.crc32(np.ascontiguousarray(arrays[name][i]))
                      for name in ("image", "depth")] for i in range(len(arrays["image"]))],
                    np.uint32).reshape(-1, 2)


def save_views(seed: int, size: tuple[int, int], arrays: dict) -> Path | None:
    """Store the arrays of :func:`load_views` atomically; returns the entry, ``None`` if the
    cache is off or the folder cannot be written (the cache is an optimisation: never fatal)."""
    n = int(len(arrays["image"]))
    path = entry_path(seed, size, n)
    if path is None:
        return None
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path.parent, prefix=f".{path.stem}.tmp-",
                                         suffix=".npz", delete=False) as f:
            tmp = Path(f.name)
            np.savez(f, key=np.array(_key(seed, size, n)), crc=_camera_crcs(arrays), **arrays)
        os.replace(tmp, path)
    except OSError:
        if tmp is not None:
            tmp.unlink(missing_ok=True)
        return None
    prune(path.parent, keep=path)
    return path
