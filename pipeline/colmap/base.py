"""What every pycolmap call shares: the pixel convention, the log level, the version.

The pipeline uses OpenCV's pixel convention (origin at the centre of the top-left pixel),
COLMAP the corner of the top-left pixel (docs/DESIGN.md "Conventions"): keypoints and principal
points get :data:`COLMAP_PIXEL_OFFSET` added on the way in and subtracted on the way out.
COLMAP's C++ log is quieted only inside the adapter's calls (:func:`quiet_colmap`), never for
the whole process.
"""

from __future__ import annotations

import errno
import os
import shutil
import signal
import threading
from contextlib import contextmanager

import numpy as np
import pycolmap

__all__ = ["COLMAP_PIXEL_OFFSET", "quiet_colmap", "version", "rigid", "write_reconstruction"]


def _default_sigterm() -> None:
    """Give SIGTERM back the action Python has for it after pycolmap's import, which installs
    glog's failure handler on it in C, behind Python's back: a ``kill`` or ``timeout`` then
    printed a C stack trace of 18 lines as if the program had crashed, and a handler set in
    Python before the import (the command line's, which cleans up on SIGTERM) never ran. The
    default action, or the Python handler, is set again; glog's handler on the signals of a
    real crash (SIGSEGV, SIGABRT, ...) is kept."""
    if threading.current_thread() is threading.main_thread():
        handler = signal.getsignal(signal.SIGTERM)
        signal.signal(signal.SIGTERM, signal.SIG_DFL if handler is None else handler)


_default_sigterm()

#: Added to OpenCV pixel coordinates to get COLMAP's (docs/DESIGN.md "Conventions").
COLMAP_PIXEL_OFFSET = 0.5


def version() -> str:
    """The pycolmap version (for the report's ``versions``)."""
    return pycolmap.__version__


@contextmanager
def quiet_colmap(level: int = 2):
    """Silence COLMAP's C++ log below ``level`` (2 = errors only) inside the block."""
    previous = pycolmap.logging.minloglevel
    pycolmap.logging.minloglevel = max(previous, level)
    try:
        yield
    finally:
        pycolmap.logging.minloglevel = previous


def rigid(R: np.ndarray, t: np.ndarray) -> pycolmap.Rigid3d:
    """``cam_from_world`` ``(R (3, 3), t (3,))`` as a ``pycolmap.Rigid3d``."""
    return pycolmap.Rigid3d(pycolmap.Rotation3d(np.asarray(R, dtype=np.float64)),
                            np.asarray(t, dtype=np.float64).reshape(3))


#: free bytes below which a failed write is put down to a full disk
_FULL_BYTES = 2**20


def _counts(rec) -> tuple[int, int, int, int]:
    return (rec.num_cameras(), rec.num_images(), rec.num_points3D(),
            rec.compute_num_observations())


def write_reconstruction(rec, path) -> None:
    """``rec.write(path)``, checked: COLMAP's writer ignores a failed write (a full disk, a
    file-size limit) and leaves truncated ``.bin`` files without a word, so the model is read
    back and compared; OSError naming ``path`` when it does not come back whole (ENOSPC when
    the disk is full)."""
    path = os.fspath(path)
    rec.write(path)
    try:
        back = _counts(pycolmap.Reconstruction(path))
    except Exception:  # noqa: BLE001 - whatever the reader makes of truncated files
        back = None
    if back == _counts(rec):
        return
    try:
        full = shutil.disk_usage(path).free < _FULL_BYTES
    except OSError:
        full = False
    if full:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), path)
    raise OSError(errno.EIO, "the COLMAP model was not written whole (a file-size limit or a "
                  "write error)", path)
