"""Shared fixtures of the real-image tests (pipeline.inputs.photos, pipeline.colmap, run-images,
clean-db) and of the labelled-landmark runs."""

import shutil
from pathlib import Path

import pytest

DATA = Path(__file__).resolve().parents[1] / "data"
SCEAUX = DATA / "sceaux_castle_640"
SCEAUX_IMAGES = ("100_7100.JPG", "100_7101.JPG", "100_7102.JPG", "100_7103.JPG")


@pytest.fixture(scope="session")
def sceaux_small(tmp_path_factory) -> Path:
    """Four Sceaux photographs at 640 px with their K.txt, copied into a fresh folder.

    The copy lives in the repository (``tests/data/sceaux_castle_640``, see its SOURCE.txt);
    the K.txt is the data set's K scaled like the images, so the folder looks like a
    full-resolution set to the code under test.
    """
    out = tmp_path_factory.mktemp("sceaux640")
    for name in (*SCEAUX_IMAGES, "K.txt"):
        shutil.copy(SCEAUX / name, out / name)
    return out


@pytest.fixture
def refuse_writes_in(monkeypatch):
    """``refuse_writes_in(folder)``: ``folder`` then takes no new file, as a read-only mount
    or ``/proc`` (for root too): the output check's write probe
    (:func:`pipeline.outputs._check_writable_folder`) is refused there."""
    from pipeline import outputs

    real = outputs.tempfile.TemporaryFile

    def apply(folder) -> None:
        def refuse(*args, dir=None, **kw):  # noqa: A002 - TemporaryFile's own keyword
            if str(dir) == str(folder):
                raise PermissionError(13, "Permission denied")
            return real(*args, dir=dir, **kw)

        monkeypatch.setattr(outputs.tempfile, "TemporaryFile", refuse)

    return apply


@pytest.fixture
def votes_remove_every_match(tmp_path) -> Path:
    """A labelled folder of three 100x100 images of two landmarks whose Hungarian matches of
    the given descriptors form one inconsistent cycle (a-b swapped, a-c and b-c not): every
    pair's two-hop vote ties with its direct one, so the votes keep no match."""
    import numpy as np
    from PIL import Image

    desc = {"a": [[-2, 1], [0, 2]], "b": [[1, 2], [1, -1]], "c": [[-2, 0], [1, -1]]}
    for name, d in desc.items():
        Image.new("L", (100, 100), 128).save(tmp_path / f"{name}.png")
        np.savetxt(tmp_path / f"{name}.txt", [[10.0, 10.0], [50.0, 50.0]])
        np.savetxt(tmp_path / f"{name}.scf", np.asarray(d, dtype=float))
    return tmp_path
