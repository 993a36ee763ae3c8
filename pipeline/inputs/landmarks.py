"""Folders of images with hand-labelled landmarks (multi-view matching benchmarks).

Every image of such a folder comes with the same ``K`` labelled keypoints in the same order
(row ``k`` is the same physical landmark in every image), so the true association of any two
images is the identity on rows. Layout:

* images: ``.png``, ``.jpg``, ``.jpeg``, ``.tif``, ``.tiff``, ``.bmp``, ``.ppm``, ``.pgm``;
* keypoints, one file per image: ``NAME.txt`` (``K`` rows ``x y``, whitespace or comma
  separated; lines ended by LF, CRLF or a carriage return alone) or ``NAME.mat`` holding
  ``pts_coord`` (``2 x K``; a MATLAB v7.3 file, HDF5, too); OpenCV pixel convention; a
  row ``nan nan`` marks a landmark the image does not see (occluded, out of view): the image
  then has a feature for each of its other rows only, and a landmark need not be seen by
  every image;
* optional descriptors, one file per image: ``NAME.scf`` (``K`` rows of numbers, separated
  like the keypoints', e.g. the
  60-bin shape contexts of the CMU hotel benchmark), or SIFT computed at the keypoints.

Pairing of the files: when every image has a keypoint file of the same stem, by name.
Otherwise (the CMU hotel files are ``hotel.seq0.png`` / ``hotel1.txt`` / ``hotel001.scf``)
by *natural* name order (``seq2`` before ``seq10``) — the ``i``-th image with the ``i``-th
keypoint file and the ``i``-th descriptor file — which needs equal counts and names that do
not tie in that order (``seq1`` and ``seq01``: a copy's place would be arbitrary), and is refused
when it would give an image another file than the one of its name, or when some files are
named after their images and an image has none of its name (order would give it another
image's file: order is for folders whose files are named after no image). An image with
two keypoint files of its name (``NAME.txt`` and ``NAME.mat``) is refused unless they hold the
same labels, and so are two images of one name (``NAME.png`` and ``NAME.jpg``), which would
both take ``NAME.txt``. Text and MAT files
that are not keypoint tables (``SOURCE.txt``, homography files, other MAT contents) are not
keypoint files and are ignored; a MAT file that lists ``pts_coord`` but cannot give it (cut
short, or a logical or sparse array) is refused, naming the file and the variable.
"""

from __future__ import annotations

import logging
import re
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.errors import InputError, listed
from pipeline.validate import check_utf8_names

__all__ = ["LandmarkFrame", "natural_key", "load_landmark_folder", "folder_image_names",
           "select_frames", "sift_at_keypoints", "IMAGE_SUFFIXES", "DESCRIPTOR_SOURCES"]

log = logging.getLogger(__name__)

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".ppm", ".pgm")
DESCRIPTOR_SOURCES = ("auto", "given", "sift")
#: most labelled landmarks per image: matching builds a K x K cost matrix per image pair
#: (5000: 200 MB in float64; labelled benchmarks carry tens to hundreds)
MAX_LANDMARKS = 5000
#: SIFT support region at a labelled keypoint: this fraction of the image's longest side
#: (the labels carry no scale; 5 % covers a local patch in both small and large images)
SIFT_SIZE_FRACTION = 0.05


@dataclass
class LandmarkFrame:
    """One image of a labelled-landmark folder.

    Attributes
    ----------
    name : str — image file name
    image_path : Path
    keypoints : ndarray, (K_i, 2) float64 — the landmarks the image sees, in label order
    landmarks : ndarray, (K_i,) int64 — the label (row of the keypoint file) of each: feature
        ``f`` of the image is landmark ``landmarks[f]`` (``0..K-1`` when it sees them all)
    descriptors : ndarray, (K_i, D) float64 or None — row ``f`` describes feature ``f``
    descriptor_kind : str — ``histogram`` (χ² distance) or ``vector`` (L2 distance)
    keypoint_file, descriptor_file : str
    """

    name: str
    image_path: Path
    keypoints: np.ndarray
    landmarks: np.ndarray | None = None
    descriptors: np.ndarray | None = None
    descriptor_kind: str = ""
    keypoint_file: str = ""
    descriptor_file: str = ""


def natural_key(name: str) -> tuple[list, str]:
    """Sort key that orders embedded numbers by value: ``a2 < a10``; names it ranks equal
    (``a1`` and ``a01``, ``A1`` and ``a1``) by the name itself, so that the order never
    depends on the order the folder lists its files in."""
    return ([(0, int(t), "") if t.isdigit() else (1, 0, t.lower())
             for t in re.split(r"(\d+)", name) if t], name)


def _table_lines(path: Path):
    """``(line number, line)`` of a label table: the lines of
    :func:`~pipeline.inputs.csvfields.text_lines`, each split at a carriage return too (a
    table of numbers has no quoted field a carriage return could belong to: a file whose lines
    end with a carriage return alone, classic Mac OS, is read as its editor shows it, and
    its line numbers are counted so)."""
    from pipeline.inputs.csvfields import text_lines

    number = 0
    for _, line in text_lines(path, "label file"):
        for piece in line.split("\r"):
            number += 1
            yield number, piece


def _number(token: str) -> float:
    """``token`` as a number written in digits 0-9 (or nan, inf); ValueError for any other
    text (Python's float() also takes "1_0" (10) and other scripts' digits)."""
    from pipeline.inputs.csvfields import NUMBER

    if not NUMBER.fullmatch(token) and token.lower().lstrip("+-") not in ("nan", "inf",
                                                                          "infinity"):
        raise ValueError(f"could not convert string to float: {token!r}")
    return float(token)


def _parse_txt_keypoints(path: Path) -> tuple[list, str | None]:
    """The rows ``[x, y]`` of a text table read up to its first line that is not two numbers,
    and that line (``"line N is '...'"``), or None when every line is two numbers; an
    unreadable file (not UTF-8, a line too long) gives no rows and no line."""
    rows: list = []
    try:
        lines = list(_table_lines(path))
    except (InputError, OSError):
        return rows, None
    for number, line in lines:
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        try:
            vals = [_number(t) for t in line.replace(",", " ").split()]
        except ValueError:
            vals = []
        if len(vals) != 2:
            count = f" ({len(vals)} numbers)" if vals else ""
            return rows, f"line {number} is {line[:60]!r}{count}"
        rows.append(vals)
    return rows, None


def _read_txt_keypoints(path: Path) -> np.ndarray | None:
    """``(K, 2)`` from a text table, ``None`` if the file is not a 2-column numeric table."""
    rows, bad = _parse_txt_keypoints(path)
    if bad is not None or not rows:
        return None
    return np.asarray(rows, dtype=np.float64)


def _txt_problem(path: Path, k: int | None = None) -> str | None:
    """Why a text file that is mostly a keypoint table is not one: its first line that is not
    two numbers, when an earlier line is, or when its rows of numbers (a header line above
    them, a third column, numbers separated by semicolons) are as many as the other label
    files' ``k`` (two or more when no label file was read) (``None`` for any other file, e.g.
    a README or a 3 x 3 homography)."""
    rows, bad = _parse_txt_keypoints(path)
    if rows or bad is None:
        return bad
    numeric = 0
    for _, line in _table_lines(path):
        toks = line.split("#", 1)[0].replace(",", " ").replace(";", " ").split()
        try:
            numeric += len([_number(t) for t in toks]) >= 2
        except ValueError:
            continue
    return bad if (numeric >= 2 if k is None else numeric == k) else None


def _why_not_table(path: Path) -> str:
    """What makes a label file of an image no keypoint table, for an error message: its first
    line that is not two numbers, that it is not UTF-8 text (UTF-16, binary: the reader's own
    message, naming the line), or that it holds no row (empty, a MAT file without
    ``pts_coord``)."""
    from pipeline.inputs.csvfields import text_lines

    if path.suffix.lower() == ".mat":
        return _why_not_mat(path)
    rows, bad = _parse_txt_keypoints(path)
    if bad is not None:
        return bad
    try:
        for _ in text_lines(path, "label file"):
            pass
    except InputError as exc:
        return str(exc)
    return "no row of two numbers in it"


#: MATLAB classes of a v7.3 variable that hold no numbers, as :func:`_read_mat_keypoints`
#: names them
_MAT73_NOT_NUMERIC = {"char": "text", "logical": "logical values", "cell": "a cell array",
                      "struct": "a struct", "function_handle": "a function handle"}


def _read_mat73_pts(path: Path) -> np.ndarray | None:
    """``pts_coord`` of a MATLAB v7.3 MAT file (an HDF5 file, ``save -v7.3``), as MATLAB holds
    it (``2 x K``); ``None`` without that variable or when HDF5 cannot read the file."""
    import h5py

    try:
        f = h5py.File(path, "r")
    except (OSError, ValueError):
        return None  # not even its HDF5 superblock: :func:`_why_not_mat` names it
    try:
        with f:
            ds = f.get("pts_coord")
            if ds is None:
                return None
            cls = ds.attrs.get("MATLAB_class", b"double")
            cls = cls.decode(errors="replace") if isinstance(cls, bytes) else str(cls)
            if isinstance(ds, h5py.Group):  # a struct or an object: an HDF5 group
                cls = "struct"
            data = None if cls in _MAT73_NOT_NUMERIC else np.asarray(ds[()])
            empty = bool(ds.attrs.get("MATLAB_empty", 0))
    except (OSError, ValueError, KeyError, TypeError, RuntimeError) as exc:
        # the file names pts_coord but its bytes are gone (a truncated copy)
        raise InputError(f"{path}: pts_coord cannot be read ({_exc_text(exc)}): a truncated or "
                         "damaged MAT file; save it again from MATLAB or SciPy, or remove "
                         "it") from None
    if data is None:
        raise InputError(f"{path}: pts_coord holds {_MAT73_NOT_NUMERIC[cls]}, expected a "
                         "numeric 2 x K array (row 0 = x, row 1 = y)")
    if empty:  # an empty matrix: the data are its sizes
        dims = data.ravel().astype(np.float64) if data.dtype.kind in "fiu" else np.zeros(0)
        if dims.size == 0 or not np.isfinite(dims).all() or (dims < 0).any() \
                or (dims != np.round(dims)).any() or (dims > 2**31).any() or dims.prod() != 0:
            raise InputError(f"{path}: pts_coord is marked empty (MATLAB_empty) but holds "
                             f"{data.ravel()[:4].tolist()}, not the sizes of an empty matrix; "
                             "save pts_coord again (a numeric 2 x K array: row 0 = x, row 1 = y)")
        return np.zeros(tuple(int(n) for n in dims), dtype=np.float64)
    if data.dtype.names == ("real", "imag"):  # complex numbers
        data = data["real"] + 1j * data["imag"]
    # MATLAB writes in column-major order: the HDF5 dataset of a 2 x K matrix is K x 2
    return data.T


#: MAT v5 data types of the numbers of an array (miINT8 .. miUINT64, miUTF8 .. miUTF32);
#: 14 is miMATRIX (an array inside a cell or struct), 15 miCOMPRESSED
_MAT5_NUMBERS = set(range(1, 14)) | {16, 17, 18}
#: MAT v5 array classes whose data are numbers or text (never arrays): char, sparse, double,
#: single, the integers
_MAT5_FLAT_CLASSES = {4, 5, *range(6, 16)}


def _mat5_problem(data: bytes) -> str | None:
    """Why a MAT v5 file's bytes must not reach SciPy's reader, or None.

    SciPy's MAT v5 reader indexes a table by each data element's type without checking it: a
    type that is no MAT data type (0, 19 and above, one damaged byte) where an array's numbers
    belong crashes the process (a segmentation fault), where any other damage raises. The
    elements are walked here (inside ``miCOMPRESSED`` ones too) and each type checked first;
    a file that is not MAT v5 (v4, v7.3, no MAT header) is left to the reader."""
    import struct
    import zlib

    if len(data) < 128 or data[126:128] not in (b"IM", b"MI") \
            or data[124:126] not in (b"\x00\x01", b"\x01\x00"):
        return None
    e = "<" if data[126:128] == b"IM" else ">"

    def elements(buf: bytes):
        pos = 0
        while pos + 8 <= len(buf):
            mdtype, nbytes = struct.unpack(e + "II", buf[pos:pos + 8])
            if mdtype >> 16:  # the small data element format: 4 bytes of data in the tag
                mdtype, nbytes = mdtype & 0xFFFF, mdtype >> 16
                yield mdtype, buf[pos + 4:pos + 4 + min(nbytes, 4)]
                pos += 8
            else:
                yield mdtype, buf[pos + 8:pos + 8 + nbytes]
                pos += 8 + (nbytes if mdtype == 15 else -(-nbytes // 8) * 8)

    def matrix(body: bytes, depth: int) -> str | None:
        if depth > 64:
            return "arrays nested more than 64 deep"
        subs = list(elements(body))
        if not subs or subs[0][0] not in _MAT5_NUMBERS or len(subs[0][1]) < 4:
            return "an array without its flags"
        flat = struct.unpack(e + "I", subs[0][1][:4])[0] & 0xFF in _MAT5_FLAT_CLASSES
        for mdtype, sub in subs[1:]:
            if mdtype == 14 and not flat:
                problem = matrix(sub, depth + 1)
                if problem:
                    return problem
            elif mdtype not in _MAT5_NUMBERS:
                return f"a data element of type {mdtype}, which is no MAT data type here"
        return None

    def top(buf: bytes, depth: int) -> str | None:
        for mdtype, body in elements(buf):
            if mdtype == 15 and depth == 0:
                try:
                    inner = zlib.decompressobj().decompress(body)
                except zlib.error:
                    continue  # the reader names a broken compressed variable itself
                problem = top(inner, depth + 1)
            elif mdtype == 14:
                problem = matrix(body, depth)
            else:
                problem = f"a variable of data type {mdtype}, not an array"
            if problem:
                return problem
        return None

    return top(data[128:], 0)


def _read_mat_keypoints(path: Path) -> np.ndarray | None:
    """``(K, 2)`` from a MAT file's ``pts_coord`` (``2 x K``), ``None`` without that variable.

    MATLAB v7.3 files (HDF5, ``save -v7.3``) are read too (:func:`_read_mat73_pts`)."""
    from scipy.io import loadmat, whosmat

    try:
        problem = _mat5_problem(path.read_bytes())
    except OSError:
        return None
    if problem is not None:
        raise InputError(f"{path}: a damaged MAT file ({problem}); save it again from MATLAB "
                         "or SciPy (pts_coord a numeric 2 x K array), or remove it")
    try:
        listed = {name: (shape, cls) for name, shape, cls in whosmat(path)}
    except NotImplementedError:  # scipy's answer to a v7.3 file: read it as HDF5
        raw = _read_mat73_pts(path)
        if raw is None:
            return None
    except Exception:  # noqa: BLE001 — no MAT file scipy can open: not a keypoint file
        if "pts_coord" in _bare_hdf5_keys(path):
            raise InputError(f"{path}: an HDF5 file holding pts_coord, but without the MAT "
                             "header MATLAB's save -v7.3 writes, so whether it is stored 2 x K "
                             "(MATLAB, column-major) or K x 2 is unknown; save it with MATLAB "
                             "or scipy.io.savemat (pts_coord 2 x K)") from None
        return None
    else:
        if "pts_coord" not in listed:
            return None
        shape, cls = listed["pts_coord"]
        if cls in _MAT5_NOT_COORDINATES:  # loadmat gives logicals as uint8 0 / 1
            raise InputError(f"{path}: pts_coord holds {_MAT5_NOT_COORDINATES[cls]}, expected "
                             "a numeric 2 x K array (row 0 = x, row 1 = y)")
        try:
            data = loadmat(path, variable_names=["pts_coord"])
            raw = np.asarray(data["pts_coord"])
        except Exception as exc:  # noqa: BLE001 — listed, so a keypoint file, but damaged
            size = " x ".join(str(n) for n in shape)
            raise InputError(f"{path}: pts_coord ({size} {cls}) cannot be read "
                             f"({_exc_text(exc)}): a truncated or damaged MAT file; save it "
                             "again from MATLAB or SciPy, or remove it") from None
    if raw.dtype.kind not in "iuf":  # text, a struct, complex numbers
        what = {"U": "text", "S": "text", "c": "complex numbers", "V": "a struct",
                "O": "a cell array", "b": "logical values"}.get(raw.dtype.kind, raw.dtype.name)
        raise InputError(f"{path}: pts_coord holds {what}, expected a numeric 2 x K array "
                         "(row 0 = x, row 1 = y)")
    pts = raw.astype(np.float64)
    if pts.ndim != 2 or pts.shape[0] != 2:
        # one row per landmark, as a text label file has them: the transpose of pts_coord
        turned = (f" (it holds {pts.shape[0]} rows 'x y': save its transpose, pts_coord')"
                  if pts.ndim == 2 and pts.shape[1] == 2 else "")
        raise InputError(f"{path}: pts_coord has shape {pts.shape}, expected 2 x K "
                         f"(row 0 = x, row 1 = y){turned}")
    return pts.T.copy()


#: MATLAB classes (as :func:`scipy.io.whosmat` names them) of a MAT v4 / v5 variable that
#: ``loadmat`` would hand over as numbers, but that hold no coordinates
_MAT5_NOT_COORDINATES = {"logical": "logical values",
                         "sparse": "a sparse matrix (save full(pts_coord) instead)"}


def _exc_text(exc: BaseException) -> str:
    """An exception as a message fragment: its text, or its type when it has none."""
    return str(exc).strip() or type(exc).__name__


def _bare_hdf5_keys(path: Path) -> list[str]:
    """The top-level names of an HDF5 file that SciPy does not take for a MAT file (no MAT
    header in its user block); ``[]`` for any other file."""
    import h5py

    try:
        if not h5py.is_hdf5(path):
            return []
        with h5py.File(path, "r") as f:
            return sorted(f.keys())
    except (OSError, ValueError, RuntimeError):
        return []


def _why_not_mat(path: Path) -> str:
    """Why a ``.mat`` file is no keypoint file, for an error message: it is no MAT file SciPy
    or HDF5 can open (their message), or it holds no variable ``pts_coord`` (its variables
    named)."""
    import h5py
    from scipy.io import whosmat

    try:
        names = [name for name, _, _ in whosmat(path)]
    except NotImplementedError:  # v7.3
        try:
            with h5py.File(path, "r") as f:
                names = sorted(k for k in f.keys() if not k.startswith("#"))
        except (OSError, ValueError, RuntimeError) as exc:
            return f"a MAT v7.3 (HDF5) file that cannot be opened: {_exc_text(exc)}"
    except Exception as exc:  # noqa: BLE001 — SciPy's reason, whatever it is
        keys = _bare_hdf5_keys(path)
        if keys:
            return f"an HDF5 file without a MAT header, holding {', '.join(keys[:5])}"
        return f"not a MAT file SciPy can read: {_exc_text(exc)}"
    held = f"it holds {listed(names, last=', ')}" if names else "it holds no variable"
    return f"no variable pts_coord; {held}"


def _check_keypoints(path: Path, pts: np.ndarray, image: Path) -> np.ndarray:
    """The rows of ``path`` the image sees, ``(K_i,)`` int64 (a row ``nan nan`` is a landmark
    it does not see); InputError if another row is not finite or lies outside ``image``, or
    if the image sees none.

    A keypoint may lie anywhere on the image's pixels in the 0-based (OpenCV, centres
    ``0..W-1``) or the 1-based (MATLAB, centres ``1..W``) convention: ``-0.5 <= x <= W + 0.5``
    and likewise for ``y``. Only the image's header is read.
    """
    from PIL import UnidentifiedImageError

    unseen = np.isnan(pts).all(axis=1)
    bad = ~np.isfinite(pts).all(axis=1) & ~unseen
    if bad.any():
        row = int(np.flatnonzero(bad)[0])
        raise InputError(f"{path}: landmark row {row + 1} is {pts[row].tolist()}; every "
                         "landmark needs finite pixel coordinates (or 'nan nan' for a landmark "
                         "this image does not see)")
    if unseen.all():
        # named with its image: files paired by name order do not say which image it labels
        raise InputError(f"{path}: every landmark row is 'nan nan': {image.name}, the image it "
                         f"labels, sees none of them; remove {image.name} from the folder with "
                         f"{path.name} (and its descriptor file), or label what it sees")
    seen = np.flatnonzero(~unseen)
    pts = pts[seen]
    from pipeline.inputs.photos import open_header

    try:
        with open_header(image) as im:  # the declared size checked, nothing decoded
            w, h = im.size
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError) as exc:
        raise InputError(f"{image.name}: cannot read it as an image ({exc}); remove or replace "
                         "the file (a truncated or non-image file)") from None
    out = (pts[:, 0] < -0.5) | (pts[:, 0] > w + 0.5) | (pts[:, 1] < -0.5) | (pts[:, 1] > h + 0.5)
    if out.any():
        row = int(np.flatnonzero(out)[0])
        # -1 -1: another tool's mark of a landmark not seen, which here is 'nan nan'
        unseen_mark = ("; if the image does not see this landmark, write the row 'nan nan' "
                       "(not -1 -1)" if (pts[row] == -1).all() else "")
        raise InputError(f"{path}: landmark row {int(seen[row]) + 1} at {pts[row].tolist()} "
                         f"lies outside the {w}x{h} image {image.name}; fix the label (pixel "
                         f"coordinates, x to the right, y down){unseen_mark}")
    return seen


def _read_descriptors(path: Path) -> np.ndarray:
    """``(rows, D)`` of a descriptor table: numbers separated by whitespace or commas, as a
    keypoint table's, in UTF-8 text (a leading byte-order mark is skipped)."""
    import io

    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(f"{path}: not a numeric table of descriptors (not UTF-8 text: "
                         f"{exc.reason} at byte {exc.start})") from None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # an empty file: its row count says it
            d = np.loadtxt(io.StringIO(text.replace(",", " ")), dtype=np.float64, ndmin=2)
    except ValueError:
        raise InputError(f"{path}: not a numeric table of descriptors "
                         f"({_first_bad_line(path)})") from None
    return d


def _first_bad_line(path: Path) -> str:
    """The first line of a descriptor table that is not all numbers, or whose count of
    numbers differs from the first line's, for an error message (lines counted from 1)."""
    width = None
    with open(path, encoding="utf-8-sig", errors="replace") as f:
        for number, line in enumerate(f, 1):
            toks = line.split("#", 1)[0].replace(",", " ").split()
            if not toks:
                continue
            try:
                [_number(t) for t in toks]
            except ValueError as exc:
                return f"line {number}: {exc}"
            if width is None:
                width = len(toks)
            elif len(toks) != width:
                return f"line {number} holds {len(toks)} values, line 1 {width}"
    return "every line must hold the same count of numbers"



def _refuse_order_mismatch(directory: Path, images: list[Path], paired: list[Path],
                           own: dict[str, Path], kind: str, pattern: str) -> None:
    """InputError when files paired by name order (``paired[i]`` with ``images[i]``) would give
    an image another file than its own: an image whose file of its name (``own``, by stem) is
    passed over, or, where some files are named after images, an image without one that takes
    another image's file (e.g. ``v3.txt`` renamed ``labels.txt``). Order is for folders whose
    files are named after no image. Two images (or two files) whose names tie in natural
    order (``seq1`` and ``seq01``, ``a1`` and ``A1``: a copy beside its original) are refused
    too: their order, and so the files they take, would be the arbitrary order of the names
    themselves, shifting every later image onto the next one's file."""
    for group, what in ((images, "images"), (paired, f"{kind} files")):
        first: dict[tuple, Path] = {}
        for p in group:
            other = first.setdefault(tuple(natural_key(p.name)[0]), p)
            if other is not p:
                raise InputError(
                    f"{directory}: {other.name} and {p.name} tie in natural name order (the "
                    "same words and numbers: leading zeros and letter case do not count), and "
                    f"the {what} pair by that order, so which {kind} file each image takes "
                    f"would be arbitrary; remove the copy or rename one, or name every {kind} "
                    f"file after its image ({pattern})")
    clash = next(((im, p) for im, p in zip(images, paired, strict=True)
                  if im.stem in own and p.stem != im.stem), None)
    if clash is not None:
        im, p = clash
        raise InputError(f"{directory}: {im.name} has the {kind} file {own[im.stem].name} by "
                         f"name, but not every image has one of its name, so they pair by name "
                         f"order, which gives it {p.name}; name every {kind} file after its "
                         f"image ({pattern}), or none")
    named = [im for im in images if im.stem in own]
    if not named:
        return
    im, p = next((im, p) for im, p in zip(images, paired, strict=True) if im.stem not in own)
    raise InputError(f"{directory}: {im.name} has no {kind} file of its name, but "
                     f"{len(named)} other image(s) have one (e.g. {named[0].name}), so they "
                     f"pair by name order, which gives it {p.name}; name every {kind} file "
                     f"after its image ({pattern}), or none")


def _refuse_shared_stem(directory: Path, images: list[Path],
                        by_stem: dict[str, tuple[Path, np.ndarray]]) -> None:
    """InputError when two images of one name (``NAME.png`` and ``NAME.jpg``) would both take
    the keypoint file ``NAME.txt`` of that name: one image's labels given to another, and
    the same view counted twice."""
    first: dict[str, Path] = {}
    for im in images:
        other = first.setdefault(im.stem, im)
        if other is not im:
            raise InputError(f"{directory}: {other.name} and {im.name} are both images of the "
                             f"keypoint file {by_stem[im.stem][0].name} (files pair with images "
                             "by name); keep one of the two images, or give each its own name "
                             "and keypoint file")


#: largest file :func:`_unsuffixed_tables` reads (a label table of 5000 rows is ~100 kB)
_TABLE_BYTES = 1 << 20


def _unsuffixed_tables(files: list[Path]) -> str:
    """A message fragment naming the files of a suffix no reader takes (``house1``, as the
    CMU house sequence names its labels, or ``labels.csv``) that hold rows of two numbers:
    label tables the reader passed over for their name; ``""`` when there are none."""
    known = {*IMAGE_SUFFIXES, ".txt", ".mat", ".scf"}
    tables = []
    for p in files:
        try:
            small = p.stat().st_size <= _TABLE_BYTES
        except OSError:
            continue
        if p.suffix.lower() not in known and small and _read_txt_keypoints(p) is not None:
            tables.append(p.name)
    if not tables:
        return ""
    return (f"; {len(tables)} file(s) hold rows 'x y' but are not named .txt "
            f"({listed(tables, 3, last=', ')}): "
            "keypoint files are read as NAME.txt, so rename them")


def _warn_orphans(directory: Path, files: list[Path], orphans: list[Path],
                  kind: str = "keypoint") -> None:
    """Warn of ``kind`` (keypoint or descriptor) files paired with no image (their image is
    missing, or of a format not read here, e.g. ``.webp``, ``.gif``): they are left out of
    the run."""
    if not orphans:
        return
    unread = [p.name for p in files
              if p.stem in {q.stem for q in orphans}
              and p.suffix.lower() not in (*IMAGE_SUFFIXES, ".txt", ".mat", ".scf")]
    why = (f"; {', '.join(unread[:3])} is not one of the image formats read "
           f"({', '.join(IMAGE_SUFFIXES)}): convert it" if unread else
           "; no image of their name")
    log.warning("warning: %s", f"{directory}: {len(orphans)} {kind} file(s) left out, "
                f"paired with no image ({', '.join(p.name for p in orphans[:5])}"
                f"{', ...' if len(orphans) > 5 else ''}){why}")


def select_frames(n_total: int, frames: int | None) -> np.ndarray:
    """Indices of ``frames`` images taken at a fixed stride from the first.

    The stride is ``floor(n_total / frames)``: frames ``0, s, 2s, ..., (frames - 1) s``, so a
    subset spans the sequence (e.g. 20 of 101 → 0, 5, …, 95). ``None``: every frame.
    """
    if frames is None:
        return np.arange(n_total)
    if frames < 2 or frames > n_total:
        raise InputError(f"--frames {frames}: expected 2..{n_total} (the folder holds "
                         f"{n_total} labelled images)")
    step = n_total // frames
    return np.arange(frames) * step


def _listing(directory: Path) -> tuple[list[Path], list[Path]]:
    """The files of a labelled folder (hidden ones left out) and its images, in natural name
    order: image ``k`` is camera ``k`` of the folder."""
    files = sorted((p for p in directory.iterdir() if p.is_file() and not p.name.startswith(".")),
                   key=lambda p: natural_key(p.name))
    return files, [p for p in files if p.suffix.lower() in IMAGE_SUFFIXES]


def folder_image_names(directory: str | Path) -> list[str]:
    """The names of a labelled folder's images in the order :func:`load_landmark_folder`
    reads them (natural name order), every one, whatever ``frames`` keeps: the images a
    graph file's indices count (:func:`pipeline.runs.landmarks.landmark_comm_graph`)."""
    return [p.name for p in _listing(Path(directory))[1]]


def load_landmark_folder(directory: str | Path, descriptors: str = "auto",
                         frames: int | None = None) -> list[LandmarkFrame]:
    """Read a labelled-landmark folder (module notes) in natural name order.

    Parameters
    ----------
    directory : folder
    descriptors : ``given`` (one ``.scf`` file per image), ``sift`` (computed at the
        keypoints, :func:`sift_at_keypoints`) or ``auto`` (``given`` when the folder holds
        ``.scf`` files, else ``sift``: a labelled set that ships only images and keypoints,
        such as the ``.mat`` files of Willow-style sets, needs no option); each frame's
        ``descriptor_file`` says which was used (``"sift"`` or the file name)
    frames : int or None — take this many images at a fixed stride (:func:`select_frames`)

    Returns
    -------
    list[LandmarkFrame], (n,) — every frame with the same ``K``

    Raises
    ------
    InputError
        Missing folder, fewer than two images, images and keypoint files that cannot be
        paired, keypoint files with different ``K``, ``given`` without one descriptor file
        per image or with a row count other than ``K``, a bad ``descriptors`` value.
    """
    directory = Path(directory)
    if descriptors not in DESCRIPTOR_SOURCES:
        raise InputError(f"--descriptors {descriptors!r}: expected one of "
                         f"{', '.join(DESCRIPTOR_SOURCES)}")
    if directory.is_file():
        raise InputError(f"{directory}: a file, not a folder; give the folder that holds the "
                         "images and their keypoint files")
    if not directory.is_dir():
        from pipeline.inputs.photos import why_missing

        why = why_missing(directory)
        raise InputError(f"{directory}: no such folder of labelled images"
                         if why == "does not exist" else f"{directory} {why}")
    files, images = _listing(directory)
    if descriptors == "auto":
        descriptors = "given" if any(p.suffix.lower() == ".scf" for p in files) else "sift"
    check_utf8_names([p.name for p in images], directory,
                     "report.json names every image in UTF-8",
                     "them (with their keypoint and descriptor files)")
    if len(images) < 2:
        subs = [p.name for p in sorted(directory.iterdir(), key=lambda p: natural_key(p.name))
                if not p.name.startswith(".") and _holds_images(p)]
        hint = (f"; its sub-folder(s) {', '.join(subs[:5])}{', ...' if len(subs) > 5 else ''} "
                "hold images: give one of them, a labelled set each" if subs else "")
        raise InputError(f"{directory}: found {len(images)} image(s); a labelled-landmark "
                         f"folder needs at least two (image + NAME.txt or NAME.mat each){hint}")
    kp_files: list[tuple[Path, np.ndarray]] = []
    rejected: dict[str, Path] = {}  # stem -> a .txt / .mat that is not a keypoint table
    for p in files:
        if p.suffix.lower() == ".txt":
            pts = _read_txt_keypoints(p)
        elif p.suffix.lower() == ".mat":
            pts = _read_mat_keypoints(p)
        else:
            continue
        if pts is not None:
            kp_files.append((p, pts))
        else:
            rejected.setdefault(p.stem, p)
    by_stem: dict[str, tuple[Path, np.ndarray]] = {}
    image_stems = {im.stem for im in images}
    for p, pts in kp_files:
        other = by_stem.setdefault(p.stem, (p, pts))
        if other[0] is not p and p.stem in image_stems and not (
                other[1].shape == pts.shape and np.array_equal(other[1], pts, equal_nan=True)):
            raise InputError(f"{directory}: {other[0].name} and {p.name} are both keypoint files "
                             f"of {p.stem} and their labels differ; keep one of them")
    if all(im.stem in by_stem for im in images):
        pairing = "name"
        _refuse_shared_stem(directory, images, by_stem)
        kps = [by_stem[im.stem] for im in images]
        _warn_orphans(directory, files, [p for p, _ in by_stem.values()
                                         if p.stem not in image_stems])
    elif len(kp_files) == len(images):
        pairing = "order"
        kps = kp_files
        _refuse_order_mismatch(directory, images, [p for p, _ in kps],
                               {stem: p for stem, (p, _) in by_stem.items()}, "keypoint",
                               "NAME.txt")
    else:
        named = [rejected[im.stem] for im in images
                 if im.stem not in by_stem and im.stem in rejected]
        if named:
            raise InputError(f"{named[0]}: not a keypoint table ({_why_not_table(named[0])}; "
                             "every line must be two numbers 'x y', or 'nan nan'; a .mat file "
                             "needs pts_coord 2 x K); fix or remove the file")
        # paired by order (the hotel's layout): a label file broken part-way names itself, and
        # so does one of as many rows of numbers as the label files read (most of them) hold
        sizes = [pts.shape[0] for _, pts in kp_files]
        k_read = max(set(sizes), key=sizes.count) if sizes else None
        broken = [(p, why) for p in sorted(rejected.values(), key=lambda q: natural_key(q.name))
                  if p.suffix.lower() == ".txt" and (why := _txt_problem(p, k_read))]
        if broken:
            raise InputError(f"{broken[0][0]}: not a keypoint table ({broken[0][1]}; every line "
                             "must be two numbers 'x y', or 'nan nan'); fix or remove the file")
        # a .mat left out may be the missing label file: say why each was
        mats = [p for p in sorted(rejected.values(), key=lambda q: natural_key(q.name))
                if p.suffix.lower() == ".mat"]
        left = "".join(f"; {p.name} was left out ({_why_not_mat(p)})" for p in mats[:3])
        left += ("; ..." if len(mats) > 3 else "") + _unsuffixed_tables(files)
        raise InputError(
            f"{directory}: {len(images)} images but {len(kp_files)} keypoint files (NAME.txt "
            f"with K rows 'x y', or NAME.mat with pts_coord 2 x K){left}; give each image a "
            "keypoint file of the same name, or exactly one per image in the same name order")
    K = {pts.shape[0] for _, pts in kps}
    if len(K) != 1:
        sizes = {p.name: pts.shape[0] for p, pts in kps}
        first = next(iter(sizes))
        other = next(n for n, k in sizes.items() if k != sizes[first])
        raise InputError(f"{directory}: keypoint files hold different numbers of landmarks "
                         f"({first}: {sizes[first]}, {other}: {sizes[other]}); every image must "
                         "carry the same labelled landmarks in the same order")
    k = next(iter(K))
    if k == 0:  # a .mat of pts_coord 2 x 0 (an empty .txt is no keypoint table)
        raise InputError(f"{kps[0][0]}: holds no landmark (pts_coord is 2 x 0); every image "
                         "needs the same K >= 1 labelled landmarks")
    if k > MAX_LANDMARKS:
        raise InputError(f"{kps[0][0]}: {k} landmarks per image; at most {MAX_LANDMARKS} "
                         "(matching compares every landmark of one image with every landmark "
                         "of another)")
    seen = [_check_keypoints(p, pts, im) for im, (p, pts) in zip(images, kps, strict=True)]
    out = [LandmarkFrame(name=im.name, image_path=im, keypoints=pts[sn], landmarks=sn,
                         keypoint_file=p.name)
           for im, (p, pts), sn in zip(images, kps, seen, strict=True)]
    if descriptors == "given":
        desc_files = [p for p in files if p.suffix.lower() == ".scf"]
        by_stem_d = {p.stem: p for p in desc_files}
        if pairing == "name" and all(im.stem in by_stem_d for im in images):
            dfiles = [by_stem_d[im.stem] for im in images]
            _warn_orphans(directory, files, [p for p in desc_files if p.stem not in image_stems],
                          "descriptor")
        elif len(desc_files) == len(images):
            dfiles = desc_files
            _refuse_order_mismatch(directory, images, dfiles, by_stem_d, "descriptor",
                                   "NAME.scf")
        else:
            # where the files are named after their images, the first image without one
            lacking = [im for im in images if im.stem not in by_stem_d]
            which = (f": {lacking[0].name} has no {lacking[0].stem}.scf"
                     + (f" ({len(lacking)} images have none)" if len(lacking) > 1 else "")
                     if lacking and len(lacking) < len(images) else "")
            raise InputError(f"{directory}: --descriptors given needs one NAME.scf per image "
                             f"(found {len(desc_files)} for {len(images)} images){which}; give "
                             "it one, or use --descriptors sift")
        first = None
        for fr, dp in zip(out, dfiles, strict=True):
            d = _read_descriptors(dp)
            if d.shape[0] != k:
                hidden = k - len(fr.landmarks)
                if hidden and d.shape[0] == len(fr.landmarks):  # rows of the seen ones only
                    raise InputError(f"{dp}: {d.shape[0]} descriptor rows for the {k} label "
                                     f"rows of {fr.keypoint_file}; {fr.name} sees "
                                     f"{d.shape[0]} landmarks, but each of its {hidden} 'nan "
                                     "nan' label rows needs a descriptor row too (any numbers: "
                                     "it is not read)")
                raise InputError(f"{dp}: {d.shape[0]} descriptor rows for {k} landmarks of "
                                 f"{fr.name}; expected one row per landmark")
            d = d[fr.landmarks]  # the rows of the landmarks it does not see are not read
            if not np.isfinite(d).all():
                row = int(fr.landmarks[np.flatnonzero(~np.isfinite(d).all(axis=1))[0]])
                raise InputError(f"{dp}: descriptor row {row + 1} holds a non-finite value "
                                 "(nan or inf); every descriptor must be finite numbers")
            # the L2 distance of two descriptors sums D squared differences in float64
            limit = np.sqrt(np.finfo(np.float64).max / (4 * max(1, d.shape[1])))
            if d.size and np.abs(d).max() > limit:
                at = np.unravel_index(int(np.argmax(np.abs(d))), d.shape)
                raise InputError(f"{dp}: descriptor row {int(fr.landmarks[at[0]]) + 1} holds "
                                 f"{d[at]:g}, too large to compare (the distance of "
                                 f"descriptors of {d.shape[1]} values overflows above "
                                 f"{limit:.3g}); the file is damaged or in other units: "
                                 "rescale it")
            first = first or (dp, d.shape[1])
            if d.shape[1] != first[1]:
                raise InputError(f"{dp}: descriptors of {d.shape[1]} values but {first[0].name} "
                                 f"has {first[1]}; every descriptor file needs the same width")
            fr.descriptors, fr.descriptor_file = d, dp.name
            # non-negative rows are histograms (shape contexts): compared by χ²
            fr.descriptor_kind = "histogram" if (d >= 0).all() else "vector"
        kinds = {fr.descriptor_kind for fr in out}
        if len(kinds) > 1:
            neg = [fr.descriptor_file for fr in out if fr.descriptor_kind == "vector"]
            log.warning("warning: %s", f"{len(neg)} of {len(out)} descriptor files hold "
                        f"negative values ({', '.join(neg[:3])}{', ...' if len(neg) > 3 else ''}"
                        "), the others none: every image's descriptors are compared by L2 "
                        "distance, not chi-square (non-negative rows are read as histograms, "
                        "e.g. shape contexts); check those files")
            for fr in out:
                fr.descriptor_kind = "vector"
    sel = select_frames(len(out), frames)
    out = [out[k] for k in sel]
    if descriptors == "sift":
        for fr in out:
            fr.descriptors = sift_at_keypoints(fr.image_path, fr.keypoints)
            fr.descriptor_kind, fr.descriptor_file = "vector", "sift"
    return out


def _holds_images(path: Path) -> bool:
    """``path`` is a folder with an image file directly in it (unreadable: no)."""
    try:
        return path.is_dir() and any(q.is_file() and q.suffix.lower() in IMAGE_SUFFIXES
                                     for q in path.iterdir())
    except OSError:
        return False


def sift_at_keypoints(image_path: str | Path, keypoints: np.ndarray) -> np.ndarray:
    """SIFT descriptors ``(K, 128)`` at the given keypoints (OpenCV ``compute``).

    The labels carry no scale or orientation: every keypoint gets the diameter
    ``SIFT_SIZE_FRACTION`` × the image's longest side and OpenCV's upright angle (0).
    """
    import cv2

    from pipeline.inputs.photos import load_image

    pixels, header = load_image(image_path)
    header.close()
    gray = pixels if pixels.ndim == 2 else cv2.cvtColor(pixels, cv2.COLOR_RGB2GRAY)
    size = SIFT_SIZE_FRACTION * max(gray.shape[:2])
    kps = [cv2.KeyPoint(float(x), float(y), float(size), 0.0) for x, y in keypoints]
    _, desc = cv2.SIFT_create().compute(gray, kps)
    if desc is None or desc.shape[0] != len(kps):
        raise InputError(f"{image_path}: SIFT could not describe every labelled keypoint "
                         "(keypoints outside the image?)")
    return desc.astype(np.float64)
