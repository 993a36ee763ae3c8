"""NumPy ``.npz`` archives read whole and without pickles (an online step's frame and history
files, :mod:`pipeline.team.online_match`, :mod:`pipeline.team.robot`)."""

from __future__ import annotations

import zipfile
import zlib

import numpy as np

__all__ = ["npz_arrays"]


def npz_arrays(path) -> dict:
    """Every array of the ``.npz`` archive at ``path``, by name.

    Raises
    ------
    ValueError
        Saying why, as ``"Kind: message"``: not readable, not a zip archive or a damaged one,
        a plain ``.npy`` file (one array), an array holding pickled objects. The caller names
        the file and what writes it.
    """
    try:
        z = np.load(path, allow_pickle=False)
        if not isinstance(z, np.lib.npyio.NpzFile):  # a plain .npy file: one array
            raise ValueError("one array (.npy), not an archive of arrays (.npz)")
        with z:
            return {k: z[k] for k in z.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as exc:
        raise ValueError(f"{type(exc).__name__}: {exc}") from None
