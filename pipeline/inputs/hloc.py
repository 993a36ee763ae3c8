"""hloc's feature and match files (HDF5) read as links, and written back cleaned.

hloc (Hierarchical-Localization) keeps local features and matches in two HDF5 files:

- ``features.h5``: one group per image, named by the image's path relative to the image folder
  (a name with ``/`` is a nested group), holding ``keypoints`` ``(N, 2)`` float in pixels with
  the origin at the centre of the top-left pixel (the OpenCV convention used here; hloc adds
  0.5 itself when it writes a COLMAP database) of the image read, whose ``(width, height)``
  is ``image_size`` (:func:`read_image_sizes`, for the recording), plus ``descriptors`` and
  ``scores``, which are not needed here.
- ``matches.h5``: one group per image pair, named ``names_to_pair(name0, name1)`` =
  ``name0/name1`` with every ``/`` inside a name replaced by ``-`` (so a pair is two nested
  groups), holding ``matches0`` ``(N0,)`` int (for each keypoint of ``name0`` the index of its
  match in ``name1``, ``-1`` for none) and optionally ``matching_scores0`` ``(N0,)`` float. Older
  hloc files name the pair ``name0_name1`` (one group); both are read. A pair may be stored in
  either order.
- ``pairs.txt``: one pair per line, ``name0 name1``.

:func:`read_h5` turns the matches into the pipeline's :class:`~pipeline.types.Links` (camera
``i`` = the ``i``-th image name in sorted order); :func:`write_cleaned_matches` writes a new
``matches.h5`` equal to the input except that the cut matches read ``-1`` (and score 0), so
hloc's ``reconstruction.main`` (or ``triangulation``) runs on it unchanged.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.errors import InputError
from pipeline.types import Links

__all__ = ["names_to_pair", "H5Matches", "read_features", "read_image_sizes", "read_pairs",
           "read_h5", "write_cleaned_matches"]


def names_to_pair(name0: str, name1: str, separator: str = "/") -> str:
    """hloc's key of an image pair in ``matches.h5`` (``separator="_"``: the older key)."""
    return separator.join((name0.replace("/", "-"), name1.replace("/", "-")))


def _h5py():
    try:
        import h5py
    except ImportError:  # pragma: no cover - h5py is a dependency
        raise InputError("reading hloc files needs h5py: pip install 'h5py>=3.10,<4'") from None
    return h5py


@contextlib.contextmanager
def _open(path: Path, what: str):
    """The HDF5 file ``path`` open for reading (``what`` names it in messages, e.g.
    ``"features file"``); an error HDF5 raises while the caller reads it (a damaged file: a
    truncated or overwritten object header, a broken B-tree) is an InputError naming it."""
    from pipeline.outputs import require_input_file

    h5py = _h5py()
    require_input_file(path, what)
    try:
        fd = h5py.File(path, "r")
    except OSError as exc:
        if "unable to lock file" in str(exc):  # HDF5's lock: another program writes it
            raise InputError(f"{what} {str(path)!r} is open for writing in another program "
                             "(HDF5's file lock: e.g. hloc still writing it, or a notebook "
                             "that opened it in mode 'a'); close it there and run again") from None
        raise InputError(f"{what} {str(path)!r} is not an HDF5 file ({exc})") from None
    with fd:
        try:
            yield fd
        except (KeyError, RuntimeError, OSError, ValueError) as exc:
            if not _raised_by_h5py(exc):
                raise
            raise InputError(f"{what} {str(path)!r} is damaged: HDF5 cannot read it "
                             f"({type(exc).__name__}: {exc}); write it again (e.g. run hloc's "
                             "extraction or matching again)") from None


def _raised_by_h5py(exc: BaseException) -> bool:
    """``exc`` was raised inside h5py (reading the file), not by this module's own code."""
    tb, last = exc.__traceback__, None
    while tb is not None:
        last, tb = tb, tb.tb_next
    return last is not None and "h5py" in Path(last.tb_frame.f_code.co_filename).parts


#: a dataset larger than this (bytes) must be backed by at least 1/:data:`MAX_EXPANSION` of
#: its size on disk: a file of a few kilobytes may declare terabytes of unwritten (fill-value)
#: data, and reading it would allocate all of it
LAZY_LIMIT_BYTES = 64 * 2**20
#: largest ratio of a dataset's size in memory to its storage in the file (gzip of a column of
#: -1 reaches a few hundred; beyond this the data is not in the file)
MAX_EXPANSION = 1024


def _read_dataset(ds, path: Path, what: str, kinds: str) -> np.ndarray:
    """Read an HDF5 dataset after checking its dtype kind and that its data is in the file.

    Parameters
    ----------
    ds : h5py.Dataset
    path : the file (for the message); what : the dataset's role, e.g. ``"keypoints of 'a'"``
    kinds : accepted numpy dtype kinds, e.g. ``"iu"`` (integers) or ``"fiu"`` (numbers)

    Raises
    ------
    InputError
        Another dtype (strings, compound, floats where integers are expected), or more
        declared data than the file stores (checked before anything is allocated).
    """
    if ds.dtype.kind not in kinds or ds.dtype.fields is not None:
        expected = "integers" if kinds == "iu" else "real numbers (integers or floats)"
        raise InputError(f"{path}: {what} have dtype {ds.dtype}; expected {expected}")
    stored = ds.id.get_storage_size()
    if ds.nbytes > LAZY_LIMIT_BYTES and stored * MAX_EXPANSION < ds.nbytes:
        raise InputError(f"{path}: {what} declare shape {ds.shape} ({ds.nbytes} bytes) but the "
                         f"file stores {stored} bytes of them; the file is damaged or not "
                         "written by hloc")
    return np.asarray(ds[()])


def _declared(fd, h5py, leaf: str) -> list:
    """Every dataset named ``leaf`` in the open file ``fd`` (metadata only, nothing read)."""
    found = []

    def visit(name, obj):
        if isinstance(name, bytes):  # h5py's name of a link that is not UTF-8
            raise InputError(f"{fd.filename}: the name {name!r} is not UTF-8 text; hloc names "
                             "its groups after the images, in UTF-8: rename that group or "
                             "dataset (or its image, and extract or match again)")
        if isinstance(obj, h5py.Dataset) and name.rsplit("/", 1)[-1] == leaf:
            found.append(obj)
    fd.visititems(visit)
    return found


def _check_declared_total(datasets, path: Path, what: str) -> int:
    """Bytes ``datasets`` declare in all; InputError when, in all, far more is declared than
    the file stores (each may stay under :data:`LAZY_LIMIT_BYTES`, their sum does not)."""
    declared = sum(int(ds.nbytes) for ds in datasets)
    stored = sum(int(ds.id.get_storage_size()) for ds in datasets)
    if declared > LAZY_LIMIT_BYTES and stored * MAX_EXPANSION < declared:
        raise InputError(f"{path}: its {len(datasets)} {what} datasets declare {declared} bytes "
                         f"in all but the file stores {stored} bytes of them; the file is "
                         "damaged or not written by hloc")
    return declared


def read_features(path: str | Path, budget=None) -> dict[str, np.ndarray]:
    """``{image name: keypoints (N, 2) float32}`` of an hloc ``features.h5``.

    ``budget``: a :class:`pipeline.budget.MemoryBudget` (handed in by the caller: inputs sit
    below the budget's layer) counting the keypoints the file declares, in all, before any
    is read.

    Raises
    ------
    InputError
        Missing or non-HDF5 file, no group with ``keypoints``, keypoints not ``(N, 2)``,
        more declared than the file stores or the budget allows.
    """
    path = Path(path)
    h5py = _h5py()
    out: dict[str, np.ndarray] = {}
    with _open(path, "features file") as fd:
        declared = _check_declared_total(_declared(fd, h5py, "keypoints"), path, "keypoints")
        if budget is not None:
            budget.add_read("the keypoints of the features file", declared)

        def visit(name, obj):
            if isinstance(obj, h5py.Dataset) and name.rsplit("/", 1)[-1] == "keypoints":
                image = obj.parent.name.strip("/")
                if not image:
                    raise InputError(f"{path}: a 'keypoints' dataset at the file's root group "
                                     "('/') belongs to no image: hloc's features.h5 holds one "
                                     "group per image, named after it, with the image's "
                                     "'keypoints'; write the keypoints so, or remove the dataset")
                what = f"keypoints of {image!r}"
                if len(obj.shape) != 2 or obj.shape[1] != 2 and obj.shape[0] != 0:
                    raise InputError(f"{path}: {what} have shape {obj.shape}; expected (N, 2)")
                kp = _read_dataset(obj, path, what, "fiu")
                if not np.isfinite(kp).all():
                    row = int(np.flatnonzero(~np.isfinite(kp).all(axis=1))[0])
                    raise InputError(f"{path}: {what}: keypoint {row} is {kp[row].tolist()}; "
                                     "every keypoint needs finite pixel coordinates")
                with np.errstate(over="ignore"):
                    kp32 = kp.reshape(-1, 2).astype(np.float32)
                if not np.isfinite(kp32).all():  # float64 past float32's range: inf once cast
                    row = int(np.flatnonzero(~np.isfinite(kp32).all(axis=1))[0])
                    raise InputError(f"{path}: {what}: keypoint {row} is {kp[row].tolist()}, "
                                     "beyond the range of pixel coordinates (float32, as hloc "
                                     "stores them); the file is damaged or not written by hloc")
                out[image] = kp32
        fd.visititems(visit)
    if not out:
        raise InputError(f"{path}: no image group with a 'keypoints' dataset; is this hloc's "
                         f"features.h5?")
    return out


def read_image_sizes(path: str | Path) -> dict[str, tuple[int, int]]:
    """``{image name: (width, height)}`` from the ``image_size`` datasets of an hloc
    ``features.h5`` (the size of the image its keypoints are in the pixels of), for the images
    that store a usable one (two whole numbers from 1 to :data:`MAX_IMAGE_SIDE`)."""
    path = Path(path)
    h5py = _h5py()
    out: dict[str, tuple[int, int]] = {}
    with _open(path, "features file") as fd:
        def visit(name, obj):
            if isinstance(obj, h5py.Dataset) and name.rsplit("/", 1)[-1] == "image_size" \
                    and obj.shape == (2,) and obj.dtype.kind in "fiu":
                size = np.asarray(obj[()], dtype=np.float64)
                if np.all((size >= 1) & (size <= MAX_IMAGE_SIDE) & (size == np.round(size))):
                    out[obj.parent.name.strip("/")] = (int(size[0]), int(size[1]))
        fd.visititems(visit)
    return out


#: largest image side an ``image_size`` dataset is believed for
MAX_IMAGE_SIDE = 100_000


def read_pairs(path: str | Path, names: set[str]) -> list[tuple[str, str]]:
    """Image pairs of an hloc ``pairs.txt`` (``name0 name1`` per line), unique, input order.

    Raises
    ------
    InputError
        Missing file, a line without two names, a name not in ``names`` (with its line).
    """
    from pipeline.inputs.csvfields import text_lines
    from pipeline.outputs import require_input_file

    path = require_input_file(path, "--pairs")
    out, seen = [], set()
    for lineno, raw in text_lines(path, "--pairs"):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        parts = line.split()
        if len(parts) != 2:
            raise InputError(f"{path}:{lineno}: {line!r} must hold two image names separated "
                             f"by white space ({len(parts)} found; hloc's pairs format: a name "
                             "holding a space cannot be written there)")
        for p in parts:
            if p not in names:
                raise InputError(f"{path}:{lineno}: image {p!r} has no keypoints in the "
                                 f"features file")
        if parts[0] == parts[1]:
            raise InputError(f"{path}:{lineno}: {line!r} pairs an image with itself")
        key = tuple(sorted(parts))
        if key not in seen:
            seen.add(key)
            out.append((parts[0], parts[1]))
    if not out:
        raise InputError(f"--pairs {str(path)!r} holds no pair")
    return out


@dataclass
class H5Matches:
    """The matches of an hloc ``matches.h5`` as links.

    Attributes
    ----------
    features_path, matches_path : Path
    names : list[str], (n,) — image names, sorted; camera ``i`` is ``names[i]``
    keypoints : list[ndarray], (n,) each (m_i, 2) float32
    links : Links, (L,) — ``cam_i < cam_j``; ``quality`` = matching score when stored
    pair_key : list[str] — the HDF5 group of each stored pair that was read
    link_pair : ndarray, (L,) int64 — index into ``pair_key`` of each link
    link_row : ndarray, (L,) int64 — row of ``matches0`` holding the link
    not_one_to_one : ndarray, (L,) bool — a second row of ``matches0`` pointing at an already
        matched keypoint (hloc's nearest-neighbour matchers allow it; Assumption 2.2 does not)
    """

    features_path: Path
    matches_path: Path
    names: list[str]
    keypoints: list[np.ndarray]
    links: Links
    pair_key: list[str]
    link_pair: np.ndarray
    link_row: np.ndarray
    not_one_to_one: np.ndarray

    @property
    def features_per_camera(self) -> np.ndarray:
        return np.array([len(k) for k in self.keypoints], dtype=np.int64)


def _find_pair(fd, a: str, b: str) -> tuple[str, bool] | None:
    """``(key, reversed)`` of the stored pair ``a, b`` (either order, new or old key)."""
    for sep in ("/", "_"):
        for x, y, rev in ((a, b, False), (b, a, True)):
            key = names_to_pair(x, y, sep)
            if key in fd and "matches0" in fd[key]:
                return key, rev
    return None


def _check_pair_groups(fd, h5py, path: Path) -> None:
    """InputError naming the first group that holds data but no ``matches0``: another tool's
    layout (e.g. ``matches`` as ``(K, 2)`` index pairs), whose pairs would otherwise be left
    out of the cleaning unread, and copied to the output as they are."""
    foreign: dict[str, list[str]] = {}

    def visit(name, obj):
        if isinstance(obj, h5py.Dataset) and "matches0" not in obj.parent:
            foreign.setdefault(obj.parent.name.strip("/"), []).append(name.rsplit("/", 1)[-1])
    fd.visititems(visit)
    if foreign and all(key and "keypoints" in held for key, held in foreign.items()):
        key = next(iter(foreign))  # the features file given as the matches file
        raise InputError(f"{path}: its {len(foreign)} group(s) of 'keypoints' without "
                         f"'matches0' (e.g. {key!r}) are images, not pairs: a features file, "
                         "not hloc's matches.h5; give the matches file as --matches")
    if foreign:
        key, held = next(iter(foreign.items()))
        where = f"group {key!r}" if key else "the file's root group ('/')"
        raise InputError(
            f"{path}: {where} holds {', '.join(repr(h) for h in held)} but no 'matches0'"
            + (f" (nor {len(foreign) - 1} other group(s))" if len(foreign) > 1 else "")
            + ": not hloc's layout, where each pair's 'matches0' gives, for every keypoint of "
            "the first image, its match in the second (-1 for none); write the matches so, or "
            + ("remove the group" if key else "remove those datasets"))


def _groups_without_keypoints(features: Path, flat_names: list[str]) -> dict[str, list[str]]:
    """``{name: its datasets}`` for each of ``flat_names`` (written as in a pair key, ``/`` as
    ``-``) whose group in the features file holds datasets but no ``keypoints``."""
    h5py = _h5py()
    wanted, out = set(flat_names), {}

    def visit(name, obj):
        if isinstance(obj, h5py.Group) and name.replace("/", "-") in wanted \
                and "keypoints" not in obj:
            held = [k for k, v in obj.items() if isinstance(v, h5py.Dataset)]
            if held:
                out[name] = held
    with _open(features, "features file") as fd:
        fd.visititems(visit)
    return out


def _stored_pairs(fd, h5py, names: list[str],
                  features: Path | None = None) -> list[tuple[str, str, str]]:
    """Every pair group of the file as ``(key, name0, name1)`` (``features``: the features
    file, to name an image whose group there holds no keypoints)."""
    where = f"matches file {fd.filename!r}"
    by_flat = {}
    for n in names:
        by_flat.setdefault(n.replace("/", "-"), []).append(n)
    keys = []

    def visit(name, obj):
        if isinstance(obj, h5py.Dataset) and name.rsplit("/", 1)[-1] == "matches0":
            keys.append(obj.parent.name.strip("/"))
    fd.visititems(visit)
    out: list[tuple[str, str, str]] = []
    seen: dict[frozenset, str] = {}
    for key in keys:
        if not key:
            raise InputError(f"{where}: a 'matches0' dataset at the file's root group ('/') "
                             "belongs to no image pair: hloc's matches.h5 holds one group per "
                             "pair, 'name0/name1', with the pair's 'matches0'; write the "
                             "matches so, or remove the dataset")
        parts = key.split("/")
        found = None
        if len(parts) == 2 and all(len(by_flat.get(p, [])) == 1 for p in parts):
            found = (by_flat[parts[0]][0], by_flat[parts[1]][0])
        elif len(parts) == 1:  # old key name0_name1: try every split at '_'
            for k in range(len(key)):
                if key[k] == "_" and len(by_flat.get(key[:k], [])) == 1 \
                        and len(by_flat.get(key[k + 1:], [])) == 1:
                    found = (by_flat[key[:k]][0], by_flat[key[k + 1:]][0])
                    break
        if found is None:
            missing = [p for p in parts if p not in by_flat] if len(parts) == 2 else \
                ([] if any(key.startswith(f + "_") or key.endswith("_" + f) for f in by_flat)
                 else [key])
            bare = _groups_without_keypoints(features, missing) if features else {}
            if bare:  # the image has a group in the features file, but no keypoints in it
                name, held = next(iter(bare.items()))
                raise InputError(f"{where}: pair group {key!r} names {name!r}, whose group "
                                 "in the features file holds no 'keypoints' dataset (only "
                                 f"{', '.join(repr(h) for h in held)}): extract the features "
                                 "of that image again, or remove the pair group")
            if missing:  # --pairs cannot help: an image the features file does not hold
                raise InputError(f"{where}: pair group {key!r} names "
                                 f"{', '.join(repr(m) for m in missing)}, not an image of the "
                                 "features file: are features.h5 and matches.h5 of the same "
                                 "images?")
            raise InputError(f"{where}: pair group {key!r} does not name two images of the "
                             f"features file; give --pairs")
        if found[0] == found[1]:
            raise InputError(f"{where}: pair group {key!r} pairs image {found[0]!r} with "
                             "itself; remove it or give --pairs")
        # one image pair in two groups (both orders, or the new key beside the old): both
        # would be read as links, and the cleaned copy of the second would lose every match;
        # hloc reads one of them, the one pairs.txt's order finds first
        pair = frozenset(found)
        if pair in seen:
            raise InputError(f"{where}: pair groups {seen[pair]!r} and {key!r} both hold "
                             f"the image pair {min(found)!r}, {max(found)!r}; give --pairs (the "
                             "group its order names is read, as hloc reads it)")
        seen[pair] = key
        out.append((key, *found))
    return out


def read_h5(features: str | Path, matches: str | Path,
            pairs: str | Path | None = None, budget=None) -> H5Matches:
    """Read hloc's ``features.h5`` and ``matches.h5`` (and optionally ``pairs.txt``).

    Parameters
    ----------
    features, matches : paths of the two HDF5 files; never modified
    pairs : pairs.txt; without it every pair stored in ``matches`` is read
    budget : a :class:`pipeline.budget.MemoryBudget` counting, before it is allocated, what
        is read: the keypoints declared in all, the robots of the images, the largest pair
        read at once, and the links of each pair before they are kept

    Returns
    -------
    H5Matches

    Raises
    ------
    InputError
        Missing or non-HDF5 files, fewer than two images, a pair of ``pairs`` not stored,
        ``matches0`` of the wrong length or naming a keypoint that does not exist (a file of no
        match is read as no link).
    """
    features, matches = Path(features), Path(matches)
    h5py = _h5py()
    kps = read_features(features, budget)
    names = sorted(kps)
    if len(names) < 2:
        raise InputError(f"{features}: {len(names)} image(s); at least two are needed")
    if budget is not None:
        budget.add_cameras(f"the robots of the {len(names)} images", len(names))
    cam = {n: k for k, n in enumerate(names)}
    m = np.array([len(kps[n]) for n in names], dtype=np.int64)
    wanted = read_pairs(pairs, set(names)) if pairs is not None else None
    ci, fi, cj, fj, q, lp, lr = [], [], [], [], [], [], []
    keys: list[str] = []
    with _open(matches, "matches file") as fd:
        found = _declared(fd, h5py, "matches0") + _declared(fd, h5py, "matching_scores0")
        _check_declared_total(found, matches, "matches")
        _check_pair_groups(fd, h5py, matches)
        if budget is not None:  # one pair is read at a time
            budget.add_read("reading the largest pair of the matches file",
                            max((ds.nbytes for ds in found), default=0))
        if wanted is None:
            stored = _stored_pairs(fd, h5py, names, features)
        else:
            stored = []
            pair_of_key: dict[str, tuple[str, str]] = {}
            for a, b in wanted:
                hit = _find_pair(fd, a, b)
                if hit is None:
                    raise InputError(f"{matches}: no matches stored for pair {a} {b} of "
                                     f"{pairs} (no group {names_to_pair(a, b)!r} nor "
                                     f"{names_to_pair(b, a)!r}); match that pair, or remove "
                                     "its line")
                key, rev = hit
                if key in pair_of_key:  # names_to_pair writes '/' inside a name as '-'
                    c, d = pair_of_key[key]
                    raise InputError(
                        f"{matches}: pairs {c} {d} and {a} {b} of {pairs} are both stored as "
                        f"group {key!r} (hloc writes a '/' inside an image name as '-'), so "
                        "one group holds the matches of one of them only; rename one of the "
                        "images (and match again), or remove one of the lines")
                pair_of_key[key] = (a, b)
                stored.append((key, b, a) if rev else (key, a, b))
        from pipeline.progress import progress

        done = set()
        for key, n0, n1 in progress(stored, desc="reading matches"):
            if key in done:
                continue
            done.add(key)
            grp = fd[key]
            ds = grp["matches0"]
            if tuple(ds.shape) != (m[cam[n0]],):  # one entry per keypoint, as hloc writes
                raise InputError(f"{matches}: matches0 of pair {key!r} has shape {ds.shape} but "
                                 f"{n0} has {m[cam[n0]]} keypoints; expected ({m[cam[n0]]},)")
            raw = _read_dataset(ds, matches, f"matches0 of pair {key!r}", "iu").reshape(-1)
            if raw.size and raw.max() >= m[cam[n1]]:
                unsigned = raw.dtype.kind == "u" and raw.max() == np.iinfo(raw.dtype).max
                raise InputError(f"{matches}: pair {key!r} matches keypoint {raw.max()} of "
                                 f"{n1}, which has {m[cam[n1]]} keypoints" + (
                                     f" ({raw.dtype} is unsigned: hloc's -1, no match, reads "
                                     f"as {raw.max()}; store matches0 as a signed integer, "
                                     "e.g. int32)" if unsigned else ""))
            if raw.dtype.kind == "u":  # the cleaned copy writes a cut match as -1 in place
                raise InputError(f"{matches}: matches0 of pair {key!r} is stored as {raw.dtype}, "
                                 "which cannot hold hloc's -1 (no match) that a cut match is "
                                 "written as; store matches0 as a signed integer, e.g. int32")
            m0 = raw.astype(np.int64)
            if raw.size and raw.min() < -1:
                raise InputError(f"{matches}: matches0 of pair {key!r} holds {raw.min()}; "
                                 "entries are -1 (no match) or a keypoint index")
            rows = np.flatnonzero(m0 >= 0)
            score = np.ones(rows.size)
            if "matching_scores0" in grp:
                sd = grp["matching_scores0"]
                if tuple(sd.shape) != (len(m0),):
                    raise InputError(f"{matches}: matching_scores0 of pair {key!r} has shape "
                                     f"{sd.shape}; expected ({len(m0)},) like matches0")
                score = _read_dataset(sd, matches, f"matching_scores0 of pair {key!r}",
                                      "fiu").astype(np.float64).reshape(-1)[rows]
                if not np.isfinite(score).all():
                    raise InputError(f"{matches}: matching_scores0 of pair {key!r} holds "
                                     f"{score[~np.isfinite(score)][0]}; scores must be finite")
            if budget is not None:
                budget.add_rows("the matches of the matches file", rows.size,
                                "give --pairs with fewer pairs")
            a, b = cam[n0], cam[n1]
            fa, fb = rows, m0[rows]
            if a > b:
                a, b, fa, fb = b, a, fb, fa
            keys.append(key)
            ci.append(np.full(rows.size, a)), fi.append(fa)
            cj.append(np.full(rows.size, b)), fj.append(fb)
            q.append(score), lp.append(np.full(rows.size, len(keys) - 1)), lr.append(rows)
    # no pair group, or none holding a match: an empty input, read as no link (clean-h5 warns
    # of it and writes the copy unchanged, as resolve warns of an empty links file)

    def cat(parts):
        return np.concatenate(parts).astype(np.int64) if parts else np.zeros(0, dtype=np.int64)

    links = Links(cat(ci), cat(fi), cat(cj), cat(fj),
                  np.concatenate(q).astype(np.float64) if q else np.zeros(0))
    # Assumption 2.2: a feature linked twice into the same other image (later rows are cut)
    n = len(names)
    offs = np.concatenate([[0], np.cumsum(m)])
    ga, gb = offs[links.cam_i] + links.feat_i, offs[links.cam_j] + links.feat_j
    first = np.zeros(len(links), dtype=bool)
    for key in (ga * n + links.cam_j, gb * n + links.cam_i):
        f = np.zeros(len(links), dtype=bool)
        f[np.unique(key, return_index=True)[1]] = True
        first = f if not first.any() else first & f
    return H5Matches(features, matches, names, [kps[x] for x in names], links, keys,
                     cat(lp), cat(lr), ~first)


def write_cleaned_matches(contents: H5Matches, out: str | Path, keep: np.ndarray) -> Path:
    """Copy ``contents.matches_path`` to ``out`` with the links not in ``keep`` removed.

    A removed link's ``matches0`` entry becomes ``-1`` and its ``matching_scores0`` 0; every
    other group and dataset is copied unchanged. Written atomically (temp file, then rename);
    ``out`` must differ from the input.
    """
    from pipeline.runfolder import publish_mode

    h5py = _h5py()
    src, out = Path(contents.matches_path), Path(out)
    keep = np.asarray(keep, dtype=bool)
    if keep.shape != (len(contents.links),):
        raise InputError(f"keep has shape {keep.shape}, expected ({len(contents.links)},)")
    if out.exists() and out.resolve() == src.resolve():
        raise InputError(f"--out {str(out)!r} is the input matches file; the input is never "
                         f"modified, choose a new file")
    out.parent.mkdir(parents=True, exist_ok=True)
    fd_tmp, tmp = tempfile.mkstemp(prefix=f".{out.name}.", suffix=".h5", dir=out.parent)
    os.close(fd_tmp)
    try:
        shutil.copyfile(src, tmp)
        cut = np.flatnonzero(~keep)
        with h5py.File(tmp, "r+") as fd:
            for p in np.unique(contents.link_pair[cut]):
                rows = np.sort(contents.link_row[cut[contents.link_pair[cut] == p]])
                grp = fd[contents.pair_key[int(p)]]
                m0 = grp["matches0"]
                m0[rows] = -1
                if "matching_scores0" in grp:
                    grp["matching_scores0"][rows] = 0
        publish_mode(tmp, directory=False)
        os.replace(tmp, out)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return out
