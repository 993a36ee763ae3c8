"""Real photographs in, :class:`~pipeline.types.View` records out.

This is the entry of the real-image path of docs/DESIGN.md ("real images:
``pipeline.inputs.photos.load_folder(dir)``"): it replaces the renderer of ``data_synth`` when a user
brings their own photos. The papers assume every robot knows its calibration; internet photo
sets do not, so each image gets its own intrinsics and says whether they are known
(``View.intrinsics_known``), which decides between the essential and the fundamental matrix in
``pipeline.matching.pairs``.

Conventions
-----------
- Images are taken in name order; camera ``i`` is the ``i``-th image (docs/DESIGN.md "Conventions").
- Pixel coordinates follow OpenCV (origin at the centre of the top-left pixel). Downscaling by
  ``s`` maps ``x + 0.5 -> s (x + 0.5)``, so ``cx' = s (cx + 0.5) - 0.5`` and ``fx' = s fx``.
- The EXIF orientation tag is not applied (as in COLMAP): pixels are used as stored, so a
  ``K.txt`` written for the stored image stays valid.
"""

from __future__ import annotations

import logging
import os
import re
import threading
import warnings
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from PIL import ExifTags, Image, UnidentifiedImageError

from pipeline.errors import InputError, listed
from pipeline.inputs.csvfields import NUMBER
from pipeline.types import View
from pipeline.validate import check_focal, check_utf8_names, focal_px_ok, is_utf8_name

__all__ = [
    "image_paths",
    "why_missing",
    "left_out_images",
    "is_utf8_name",
    "identical_pixels",
    "pixel_digests",
    "IMAGE_SUFFIXES",
    "CAMERA_FORMATS",
    "MIN_MAX_SIZE",
    "GUESS_FOCAL_FACTOR",
    "guess_K",
    "ImageIntrinsics",
    "load_folder",
    "load_image",
    "exif_orientation",
    "as_oriented",
    "read_k_txt",
    "warn_misnamed_k_txt",
    "exif_focal_px",
    "in_content_order",
]

log = logging.getLogger(__name__)

#: File suffixes taken as images (case-insensitive); other files in the folder are skipped.
#: ``.jfif`` and ``.jpe`` are JPEG files too (a browser on Windows saves a photo as
#: ``.jfif``): left out, they were warned with the advice to convert them to JPEG.
IMAGE_SUFFIXES = (".jpg", ".jpeg", ".jfif", ".jpe", ".png", ".tif", ".tiff", ".bmp", ".webp")
#: Suffixes of camera files Pillow does not open (so not in its registered extensions): a
#: phone's HEIC / HEIF, JPEG XL, and raw files (DNG and the makers' own). Beside the
#: photographs they are left out as any other format is, and warned as such.
CAMERA_FORMATS = (".heic", ".heif", ".hif", ".jxl", ".dng", ".cr2", ".cr3", ".crw", ".nef",
                  ".nrw", ".arw", ".srf", ".sr2", ".raf", ".orf", ".rw2", ".pef", ".srw",
                  ".x3f", ".3fr", ".iiq", ".erf", ".mos", ".raw")
#: the smallest longest side images may be downscaled to (``max_size``)
MIN_MAX_SIZE = 16
#: Focal length of the stated guess, in units of the longest image side.
GUESS_FOCAL_FACTOR = 1.2
#: Diagonal of the 35 mm film frame (36 x 24 mm), the reference of ``FocalLengthIn35mmFilm``.
_FILM_DIAGONAL_MM = float(np.hypot(36.0, 24.0))
#: EXIF ``FocalPlaneResolutionUnit`` values -> millimetres per unit.
_EXIF_UNIT_MM = {2: 25.4, 3: 10.0, 4: 1.0, 5: 1e-3}
#: Most pixels an image may declare: decoding holds them all at full resolution (3 bytes
#: each in RGB, 8 in 16-bit RGBA) before any downscaling; 100 megapixels is a
#: medium-format photograph.
MAX_IMAGE_PIXELS = 100_000_000
#: An image file may be at most this many times the bytes of its decoded pixels, plus
#: :data:`FILE_HEADROOM_BYTES` (metadata, an embedded preview); an uncompressed TIFF or PNG
#: is about once its pixels. A larger file holds something else (a 1 GB file behind a
#: 640x480 JPEG header), and is refused without reading it.
MAX_FILE_TO_PIXELS = 4
FILE_HEADROOM_BYTES = 16 * 2**20
#: A K.txt whose principal point lies further than this fraction of an image's side from its
#: centre is warned (a calibrated lens has it within a few percent): the usual cause is a
#: K.txt of the full-resolution photos beside resized copies.
OFF_CENTRE = 0.2
#: A K.txt whose skew ``K[0, 1]`` exceeds this fraction of ``fx`` is refused. The skew is
#: ``fx cot(theta)``, ``theta`` the angle between the sensor's pixel axes: 0 on any modern
#: camera, and COLMAP's and OpenCV's pinhole models have none (the COLMAP stages leave it
#: out). 0.1 is axes more than 5.7 degrees from square, which no sensor has: such a value is
#: a number in the wrong place of the matrix (``cx`` written where the skew goes) or another
#: unit. A calibration that estimated a skew gives a fraction of a percent of ``fx``.
MAX_SKEW_FRACTION = 0.1
#: A K.txt whose ``fy / fx`` lies outside ``[1 / MAX_FOCAL_RATIO, MAX_FOCAL_RATIO]`` is refused.
#: The two are one focal length over the pixel's height and width: equal on square pixels
#: (a calibration gives them within a percent or so), an anamorphic lens squeezing at most 2x.
#: The COLMAP stages use one focal length, ``sqrt(fx fy)``, and matching and fusion both:
#: further apart, the stages see two different cameras, and the value is a digit lost or
#: added (Sceaux's six 320 px photos with ``fy = 10 fx``: the run went on and flagged its
#: cleaning as worse; with ``fy = fx / 10`` fusion cut three times the links).
MAX_FOCAL_RATIO = 2.0
#: Deeper-than-8-bit pixels are stretched to 0..255 from ``100 -`` this percentile of their
#: values up to this one (:func:`_to_uint8`): the brightest 0.1 % (hot or saturated pixels)
#: and the darkest saturate instead of setting the scale of the whole image.
DEEP_STRETCH_PERCENTILE = 99.9
#: the percentiles are taken on at most this many of an image's values, evenly spaced
DEEP_STRETCH_SAMPLE = 4_000_000


@dataclass
class ImageIntrinsics:
    """Where the intrinsics of one image came from.

    Attributes
    ----------
    K : ndarray, (3, 3) float64 — at the image's full (stored) resolution
    source : str — ``K.txt``, ``exif-35mm``, ``exif-focal-plane`` or ``guess``
    known : bool — ``False`` for the guess
    """

    K: np.ndarray
    source: str
    known: bool


# --------------------------------------------------------------------------------------- images

def image_paths(directory: Path) -> list[Path]:
    """The image files of ``directory`` by suffix, in name order (hidden files left out);
    nothing is checked: :func:`load_folder` says what is wrong with a folder."""
    return [p for p in _visible_files(directory) if p.suffix.lower() in IMAGE_SUFFIXES]


def left_out_images(directory: Path, robot_folder: bool = False) -> list[str]:
    """What in ``directory`` looks like a photograph but is not read (another image format, a
    link leading nowhere, a sub-folder holding images), one phrase each, for a warning;
    ``robot_folder``: ``directory`` is a robot's folder of ``--sequence``."""
    return _left_out_images(directory, _visible_files(directory), robot_folder)


def _visible_files(directory: Path) -> list[Path]:
    return sorted((p for p in directory.iterdir() if p.is_file() and not p.name.startswith(".")),
                  key=lambda p: p.name)


def why_missing(path: Path) -> str:
    """Why ``path``, which does not exist, names nothing: ``does not exist``, or the symbolic
    link on its way that leads nowhere (a photo folder linked to a drive not mounted), named
    with its target: "does not exist" alone sent the user looking at a link they can see."""
    import errno

    path = Path(path)
    for link in (path, *path.parents):
        if link.is_symlink() and not link.exists():
            what = "is" if link == path else f"does not exist: {str(link)!r} on its way is"
            try:
                os.stat(link)
            except OSError as exc:
                if exc.errno == errno.ELOOP:
                    return (f"{what} a symbolic link that leads back to itself (to "
                            f"{os.readlink(link)!r}, a loop of links); make it lead to a "
                            "file or folder")
            return (f"{what} a symbolic link that leads nowhere (to {os.readlink(link)!r}); "
                    "mount or create its target")
    return "does not exist"


def _image_files(directory: Path) -> list[Path]:
    if not directory.exists():
        raise InputError(f"image folder {str(directory)!r} {why_missing(directory)}")
    if not directory.is_dir():
        raise InputError(f"{str(directory)!r} is not a folder: give the folder that holds the images")
    files = _visible_files(directory)
    images = image_paths(directory)
    skipped = [p.name for p in files if p.suffix.lower() not in IMAGE_SUFFIXES]
    if skipped:
        log.info("skipping %d file(s) that are not images by suffix: %s", len(skipped),
                 ", ".join(skipped))
    left_out = _left_out_images(directory, files)
    if left_out:
        log.warning("warning: %s", f"{str(directory)!r}: {'; '.join(left_out)}")
    if not images:
        subs = [p for p in directory.iterdir() if p.is_dir() and not p.name.startswith(".")]
        hint = (f"; it holds {len(subs)} sub-folder(s): for one sub-folder of frames per "
                "robot, add --sequence" if subs else "")
        raise InputError(
            f"no images in {str(directory)!r}: expected files ending in "
            f"{', '.join(IMAGE_SUFFIXES)} (found {len(files)} other file(s)){hint}")
    check_utf8_names([p.name for p in images], directory,
                     "the outputs name every image in UTF-8 (report.json, COLMAP's model)")
    if len(images) == 1:
        raise InputError(
            f"only one image in {str(directory)!r} ({images[0].name}): matching needs at least "
            f"two cameras; add more images" + (f" ({'; '.join(left_out)})" if left_out else ""))
    return images


def _holds_images(path: Path) -> bool:
    try:
        return path.is_dir() and bool(image_paths(path))
    except OSError:  # an unreadable sub-folder: nothing read from it either
        return False


def _left_out_images(directory: Path, files: list[Path], robot_folder: bool = False) -> list[str]:
    """What in ``directory`` looks like a photograph but is not read, for a warning: files of
    another image format Pillow knows (GIF, PPM, ...: not a photo format COLMAP's tools take
    here) or a camera's that it does not (:data:`CAMERA_FORMATS`: HEIC, raw), symbolic links
    that lead nowhere, and sub-folders holding images (one folder per robot is
    ``--sequence``)."""
    from PIL import Image

    known = (set(Image.registered_extensions()) | set(CAMERA_FORMATS)) - set(IMAGE_SUFFIXES)
    out = []
    other = [p.name for p in files if p.suffix.lower() in known]
    if other:
        out.append(f"{len(other)} image file(s) of a format not read here left out "
                   f"({', '.join(other[:5])}{', ...' if len(other) > 5 else ''}; convert them "
                   f"to one of {', '.join(IMAGE_SUFFIXES)})")
    entries = sorted((p for p in directory.iterdir() if not p.name.startswith(".")),
                     key=lambda p: p.name)
    broken = [p.name for p in entries if p.is_symlink() and not p.exists()]
    if broken:
        out.append(f"{len(broken)} symbolic link(s) leading nowhere left out "
                   f"({', '.join(broken[:5])}{', ...' if len(broken) > 5 else ''})")
    # named like a photograph but no file to read (x.jpg a FIFO: reading it would wait for
    # a writer for ever)
    special = [p.name for p in entries if p.suffix.lower() in known | set(IMAGE_SUFFIXES)
               and p.exists() and not p.is_file() and not p.is_dir()]
    if special:
        out.append(f"{len(special)} entry(ies) named like images but not regular files (a "
                   f"FIFO, device or socket) left out ({listed(special, last=', ')}; give "
                   "the photographs as files)")
    subs = [p.name for p in entries if _holds_images(p)]
    if subs:
        hint = ("a robot's frames lie directly in its own sub-folder of the --sequence folder"
                if robot_folder else "one sub-folder of frames per robot is --sequence")
        out.append(f"{len(subs)} sub-folder(s) holding images left out ({', '.join(subs[:5])}"
                   f"{', ...' if len(subs) > 5 else ''}; {hint})")
    return out


def _to_uint8(arr: np.ndarray) -> np.ndarray:
    """Map any integer/float pixel array to uint8.

    8-bit data is returned as is. Deeper data (16-bit PNG/TIFF, gray or colour
    (:func:`_deep_color_pixels`), 32-bit integer or float) is
    stretched linearly from its ``100 -`` :data:`DEEP_STRETCH_PERCENTILE`-th to its
    :data:`DEEP_STRETCH_PERCENTILE`-th percentile (darker and brighter pixels saturate),
    because many 16-bit cameras use only 10–12 bits and a fixed ``/ 257`` would leave the
    image nearly black (few SIFT detections); the maximum itself is no bound, since one hot or
    saturated pixel at 65535 in 10-bit data would leave every other pixel below 5 of 255, an
    image without a single feature. Nor is 0 the bottom: data on a pedestal (a thermal
    camera's counts, 7000 to 8000 of 65535; a sensor's black level) stretched from 0 kept an
    eighth of the range, and on Sceaux photographs so stored SIFT found 44 features an image
    where it found 750 in the 8-bit copies (no image registered). Negative values (signed or
    float data) are stretched alike; NaN and infinite values (a float image's mask) take no
    part in the percentiles and are drawn black.
    """
    if arr.dtype == np.uint8:
        return arr
    a = arr.astype(np.float64)
    finite = np.isfinite(a)
    if not finite.any():
        return np.zeros(arr.shape, dtype=np.uint8)
    # the scale is the finite values' (a float image's NaN mask is no pixel value), and the
    # others are drawn black
    values = a[finite] if not finite.all() else a.ravel()
    sample = values[::max(1, values.size // DEEP_STRETCH_SAMPLE)]
    low, high = np.percentile(sample, [100.0 - DEEP_STRETCH_PERCENTILE, DEEP_STRETCH_PERCENTILE])
    lo, hi = float(low), float(high)
    if hi <= lo:  # the image is flat but for a few pixels: those are its content
        lo, hi = float(values.min()), float(values.max())
    a[~finite] = lo
    if hi <= lo:
        return np.zeros(arr.shape, dtype=np.uint8)
    return np.clip(np.rint((a - lo) * (255.0 / (hi - lo))), 0, 255).astype(np.uint8)


def _pixels(im: Image.Image) -> np.ndarray:
    """(H, W) gray or (H, W, 3) RGB uint8 pixels of a decoded Pillow image; alpha dropped."""
    mode = im.mode
    if mode in ("L", "RGB"):
        return np.asarray(im)
    if mode in ("1", "P", "PA", "LA", "La"):
        im = im.convert("RGBA" if mode in ("P", "PA") else "L")
        arr = np.asarray(im)
        return arr[..., :3] if arr.ndim == 3 else arr
    if mode in ("RGBA", "RGBa", "RGBX", "CMYK", "YCbCr", "LAB", "HSV"):
        return np.asarray(im.convert("RGB"))
    # I;16, I;16B, I;16L, I;16N, I (int32), F (float32): single-channel deep images
    arr = np.asarray(im)
    if arr.ndim == 3:
        arr = arr[..., :3]
    return _to_uint8(arr)


_PILLOW_LIMIT = threading.Lock()


def _first_notes(notes: list[str]) -> str:
    """Pillow's warnings about one file, as one warning of ours quotes them: the first three,
    then an ellipsis."""
    return "; ".join(notes[:3]) + ("; …" if len(notes) > 3 else "")


def open_header(path: str | Path) -> Image.Image:
    """``Image.open`` (the header only) and the size check of :func:`_check_declared_size`.

    Pillow's own decompression-bomb check is off for the open: above about 179 M pixels it
    raised its own error before this check could name the size and the limit (README, "Errors
    you can meet"); the check here refuses from :data:`MAX_IMAGE_PIXELS` on, before anything
    is decoded. UnidentifiedImageError / OSError as ``Image.open`` raises them."""
    import warnings

    path = Path(path)
    with _PILLOW_LIMIT, warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("ignore", Image.DecompressionBombWarning)
        warnings.simplefilter("always", UserWarning)  # Pillow's, said once below
        limit, Image.MAX_IMAGE_PIXELS = Image.MAX_IMAGE_PIXELS, None
        try:
            im = Image.open(path)
        finally:
            Image.MAX_IMAGE_PIXELS = limit
    notes = sorted({str(w.message).strip() for w in said
                    if issubclass(w.category, UserWarning)
                    and not issubclass(w.category, Image.DecompressionBombWarning)})
    if notes:  # a damaged header (TIFF tags, EXIF): read as far as it goes, named once
        log.warning("warning: %s", f"{path.name}: its header is damaged (Pillow: "
                    f"{_first_notes(notes)}); what could be read is used")
    _check_declared_size(path, im)
    return im


def _check_declared_size(path: Path, im: Image.Image) -> None:
    """InputError, before anything is decoded, for an image declaring more than
    :data:`MAX_IMAGE_PIXELS` pixels or a file far larger than the pixels it declares."""
    w, h = im.size
    if w * h > MAX_IMAGE_PIXELS:
        im.close()
        raise InputError(f"{path.name}: declares {w}x{h} = {w * h:,} pixels, above the "
                         f"{MAX_IMAGE_PIXELS:,} an image may have (decoding holds them all); "
                         "downscale it, or remove it")
    decoded = w * h * max(len(im.getbands()), 1) * (2 if "16" in im.mode else 1)
    size = path.stat().st_size
    if size > MAX_FILE_TO_PIXELS * decoded + FILE_HEADROOM_BYTES:
        im.close()
        raise InputError(f"{path.name}: {size:,} bytes for a {w}x{h} image ({decoded:,} bytes "
                         "of pixels); the file holds something else than that image: remove "
                         "or replace it")


def _tiff_layout(path: Path) -> str | None:
    """What the first image of a TIFF file holds, read from its header (``32-bit
    floating-point TIFF, 3 samples per pixel``), or ``None``: not a TIFF, or no readable
    header. Names a layout Pillow cannot open (32-bit float RGB) without decoding it."""
    import struct

    tags = {}
    try:
        with open(path, "rb") as f:
            head = f.read(8)
            if head[:4] not in (b"II*\0", b"MM\0*"):
                return None
            e = "<" if head[:2] == b"II" else ">"
            f.seek(struct.unpack(e + "I", head[4:])[0])
            for _ in range(min(struct.unpack(e + "H", f.read(2))[0], 4096)):
                tag, typ, count, value = struct.unpack(e + "HHI4s", f.read(12))
                if tag not in (258, 277, 339) or typ != 3:  # BitsPerSample, SamplesPerPixel,
                    continue                                  # SampleFormat: SHORTs
                if count > 2:  # one value per sample, stored apart: the first one
                    here = f.tell()
                    f.seek(struct.unpack(e + "I", value)[0])
                    value = f.read(2)
                    f.seek(here)
                tags[tag] = struct.unpack(e + "H", value[:2])[0]
    except (OSError, struct.error):
        return None
    kind = {1: "unsigned integer", 2: "signed integer", 3: "floating-point"}.get(
        tags.get(339, 1), "other-sample-format")
    return f"{tags.get(258, 1)}-bit {kind} TIFF, {tags.get(277, 1)} sample(s) per pixel"


#: ISO-BMFF ``ftyp`` brands of HEIC / HEIF stills and sequences (ISO/IEC 23008-12)
_HEIF_BRANDS = (b"heic", b"heix", b"heim", b"heis", b"hevc", b"hevx", b"hevm", b"hevs",
                b"mif1", b"msf1")


def _heif_brand(path: Path) -> str | None:
    """The major brand of a HEIC / HEIF file (``heic``), read from its ``ftyp`` box, or
    ``None``: a phone's photo renamed ``.jpg`` was refused as "a truncated or non-image
    file"."""
    try:
        with open(path, "rb") as f:
            head = f.read(12)
    except OSError:
        return None
    if len(head) == 12 and head[4:8] == b"ftyp" and head[8:12] in _HEIF_BRANDS:
        return head[8:12].decode("ascii")
    return None


def _deep_color(im: Image.Image) -> bool:
    """Whether ``im`` (opened, not yet loaded) is a 16-bit-per-channel colour PNG or TIFF:
    Pillow decodes those to 8 bits by keeping each sample's high byte, so 10- or 12-bit data
    stored in 16 bits comes out at 0..3 or 0..15 of 255, an image without a feature."""
    if im.mode not in ("RGB", "RGBA"):
        return False
    for tile in im.tile:
        args = tile[3]
        raw = args[0] if isinstance(args, tuple) and args else args
        if isinstance(raw, str) and ";16" in raw:
            return True
    return False


def _deep_color_pixels(path: Path, im: Image.Image) -> np.ndarray:
    """The (H, W, 3) uint8 RGB pixels of a 16-bit colour file (:func:`_deep_color`), from all
    16 bits (OpenCV reads them) stretched as :func:`_to_uint8` stretches deep gray images;
    Pillow's 8-bit pixels where OpenCV cannot read the file as Pillow did."""
    data = np.fromfile(path, dtype=np.uint8)
    arr = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    w, h = im.size
    if arr is None or arr.dtype != np.uint16 or arr.ndim != 3 or arr.shape[:2] != (h, w) \
            or arr.shape[2] not in (3, 4):
        return _pixels(im)
    return _to_uint8(arr[..., 2::-1])  # BGR(A) -> RGB, alpha dropped


def _decode(path: Path, im: Image.Image) -> np.ndarray:
    """The pixels of ``im`` (opened by :func:`open_header`), decoded in full (a truncated
    JPEG raises here, not later), and its frames counted (a TIFF reads its pages' headers).
    Pillow's warnings meanwhile (a damaged EXIF block of a TIFF, a frame above Pillow's
    decompression-bomb limit, ...) are said as one warning naming the file, as
    :func:`open_header` says those of the header; other warnings are warned again as they
    were."""
    with _PILLOW_LIMIT, warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        deep = _deep_color(im)
        im.load()
        pixels = _pixels(im) if not deep else _deep_color_pixels(path, im)
        getattr(im, "n_frames", 1)  # after the pixels: a TIFF seeks its pages to count them
    pillow = str(Path(Image.__file__).parent)
    notes = []
    for w in said:
        if str(w.filename).startswith(pillow):  # raised in Pillow's own code
            notes.append(" ".join(str(w.message).split()).rstrip("."))
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    notes = sorted(set(notes))
    if notes:
        log.warning("warning: %s", f"{path.name}: decoding it, Pillow warned: "
                    f"{_first_notes(notes)}; the image as decoded is used")
    return pixels


def load_image(path: str | Path) -> tuple[np.ndarray, Image.Image]:
    """Decode one image file completely.

    Parameters
    ----------
    path : path of a JPEG, PNG or TIFF file

    Returns
    -------
    pixels : ndarray, (H, W) uint8 gray or (H, W, 3) uint8 RGB, at full resolution
    header : PIL.Image.Image — the opened file (for EXIF); its pixel data is already loaded

    Pillow's warnings while the header is read (:func:`open_header`) and while the pixels
    are decoded (a damaged EXIF block of a TIFF, a frame above Pillow's decompression-bomb
    limit, ...) are each said as one warning naming the file, never as Pillow's raw lines.

    Raises
    ------
    InputError
        The file is not an image Pillow can decode (a TIFF whose header Pillow cannot read is
        named by its layout, e.g. 32-bit float RGB), or it is truncated / corrupt; it declares
        more than :data:`MAX_IMAGE_PIXELS`, or the file is far larger than its pixels
        (checked on the header, before decoding).
    """
    path = Path(path)
    try:
        if path.stat().st_size == 0:
            raise InputError(f"{path.name}: the file is empty (0 bytes), not an image; remove or "
                             "replace it (an interrupted copy or download?)")
        im = open_header(path)
        pixels = _decode(path, im)
    except InputError:
        raise
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError, Image.DecompressionBombError) as exc:
        tiff = _tiff_layout(path) if isinstance(exc, UnidentifiedImageError) else None
        if tiff is not None:
            raise InputError(
                f"{path.name}: {tiff}: not a layout this reader decodes; convert it to an 8- "
                f"or 16-bit PNG or TIFF (e.g. magick {path.name} -depth 16 {path.stem}.png)"
            ) from None
        heif = _heif_brand(path) if isinstance(exc, UnidentifiedImageError) else None
        if heif is not None:
            raise InputError(
                f"{path.name}: a HEIC/HEIF image (brand {heif!r} in its header), whatever its "
                "suffix says; this reader does not decode HEIC: convert it to JPEG (e.g. "
                f"magick {path.name} {path.stem}-converted.jpg), or export the photos from the "
                "phone as JPEG") from None
        raise InputError(
            f"{path.name}: cannot read it as an image ({exc}); remove or replace the file "
            f"(a truncated or non-image file)") from None
    if pixels.ndim not in (2, 3) or min(pixels.shape[:2]) < 2:
        size = f"{pixels.shape[1]}x{pixels.shape[0]}" if pixels.ndim in (2, 3) else \
            f"of shape {pixels.shape}"
        raise InputError(f"{path.name}: a {size} image (fewer than 2 pixels on a side) is no "
                         "photograph and holds no feature; remove or replace it")
    return np.ascontiguousarray(pixels), im


def exif_orientation(header: Image.Image) -> int:
    """The EXIF orientation tag of an opened image, 1 to 8; 1 (as stored) where it has none
    or one that is no orientation (a damaged block)."""
    try:
        with warnings.catch_warnings():  # a damaged EXIF block: Pillow's notes were said
            warnings.simplefilter("ignore", UserWarning)  # by open_header already
            tag = header.getexif().get(ExifTags.Base.Orientation, 1)
    except Exception:  # noqa: BLE001 - a broken EXIF block just means "no EXIF"
        return 1
    tag = _exif_int(tag)
    return tag if tag is not None and 1 <= tag <= 8 else 1


def as_oriented(pixels: np.ndarray, orientation: int) -> np.ndarray:
    """``pixels`` as a viewer shows them under the EXIF ``orientation`` tag (what OpenCV's
    ``imread`` returns, and so what hloc's features were extracted from); this pipeline's
    own stages use the pixels as stored (module notes). Pillow's ``ImageOps.exif_transpose``
    turns them, on an image that carries its EXIF block."""
    from PIL import ImageOps

    if orientation == 1:
        return pixels
    im = Image.fromarray(np.ascontiguousarray(pixels))
    exif = Image.Exif()
    exif[ExifTags.Base.Orientation] = orientation
    im.info["exif"] = exif.tobytes()
    return np.ascontiguousarray(np.asarray(ImageOps.exif_transpose(im)))


# ----------------------------------------------------------------------------------- intrinsics

def read_k_txt(path: str | Path) -> np.ndarray:
    """Read pinhole intrinsics from a text file.

    Accepted layouts: the 3x3 matrix ``fx 0 cx / 0 fy cy / 0 0 1`` (the Sceaux ``K.txt``;
    a skew ``s`` in ``K[0, 1]`` with ``|s| <= MAX_SKEW_FRACTION * fx`` (0.1) is kept), or the
    four numbers ``fx fy cx cy`` on one line.
    Separators may be spaces, tabs or commas; ``#`` starts a comment.

    Returns
    -------
    K : ndarray, (3, 3) float64

    Raises
    ------
    InputError
        The file is missing, does not hold 9 or 4 numbers, the last row is not ``0 0 1``,
        ``K[1, 0]`` is not 0, a focal length is not positive, ``fx`` and ``fy`` are more than
        :data:`MAX_FOCAL_RATIO` times apart, or the skew ``K[0, 1]`` is larger than
        :data:`MAX_SKEW_FRACTION` times ``fx`` (the COLMAP stages, whose pinhole has no skew
        and one focal length, would leave out what the others use: pixel axes that far from
        square are a number in the wrong place).
    """
    path = Path(path)
    if path.is_dir():
        raise InputError(f"intrinsics file {str(path)!r} is a folder; give the K.txt file")
    if not path.is_file():
        if path.exists():  # open() would wait on a FIFO for a writer that never comes
            raise InputError(f"intrinsics file {str(path)!r} is not a regular file (a FIFO, "
                             "device or socket); give the K.txt file")
        raise InputError(f"intrinsics file {str(path)!r} {why_missing(path)}")
    from pipeline.inputs.csvfields import text_lines

    try:  # a UTF-8 BOM (Notepad) is read; UTF-16 and Latin-1 text are named as such
        lines = [line for _, line in text_lines(path, "intrinsics file")]
    except OSError as exc:
        raise InputError(f"intrinsics file {str(path)!r} cannot be read ({exc.strerror or exc})"
                         ) from None
    tokens = [t for line in lines for t in re.split(r"[\s,;]+", line.split("#")[0]) if t]
    # digits 0-9 as a text file writes them: Python's float() also takes "7_0" (70) and other
    # scripts' digits
    bad = next((t for t in tokens if not NUMBER.fullmatch(t)
                and t.lower().lstrip("+-") not in ("nan", "inf", "infinity")), None)
    if bad is not None:
        raise InputError(
            f"intrinsics file {str(path)!r}: {bad!r} is not a number; expected the 3x3 matrix "
            f"'fx 0 cx / 0 fy cy / 0 0 1' or 'fx fy cx cy'")
    values = np.array([float(t) for t in tokens], dtype=np.float64)
    if values.size == 4:
        fx, fy, cx, cy = values
        K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    elif values.size == 9:
        K = values.reshape(3, 3)
    else:
        raise InputError(
            f"intrinsics file {str(path)!r} holds {values.size} numbers; expected 9 (the 3x3 "
            f"matrix 'fx 0 cx / 0 fy cy / 0 0 1') or 4 ('fx fy cx cy')")
    if not np.all(np.isfinite(K)):
        raise InputError(f"intrinsics file {str(path)!r}: non-finite value in K = {K.tolist()}")
    if not np.allclose(K[2], [0.0, 0.0, 1.0]) or K[1, 0] != 0.0:
        raise InputError(
            f"intrinsics file {str(path)!r}: K = {K.tolist()} is not a pinhole matrix "
            f"(expected the rows 'fx s cx', '0 fy cy', '0 0 1')")
    if K[0, 0] <= 0 or K[1, 1] <= 0:
        raise InputError(f"intrinsics file {str(path)!r}: focal lengths must be positive, got "
                         f"fx={K[0, 0]}, fy={K[1, 1]}")
    ratio = K[1, 1] / K[0, 0]
    if not 1.0 / MAX_FOCAL_RATIO <= ratio <= MAX_FOCAL_RATIO:
        raise InputError(
            f"intrinsics file {str(path)!r}: fy = {K[1, 1]:g} is {ratio:.3g} x fx ({K[0, 0]:g}); "
            "fx and fy are one focal length over the pixels' width and height, nearly equal on "
            f"any camera (an anamorphic lens: at most {MAX_FOCAL_RATIO:g}x apart), and the "
            "COLMAP stages use one, sqrt(fx fy): a digit lost or added? give fx and fy of the "
            "calibration")
    skew = K[0, 1]
    if abs(skew) > MAX_SKEW_FRACTION * K[0, 0]:
        raise InputError(
            f"intrinsics file {str(path)!r}: skew K[0, 1] = {skew:g} is {abs(skew) / K[0, 0]:.3g} "
            f"x fx ({K[0, 0]:g}); a camera's skew is 0 (COLMAP's and OpenCV's pinhole have "
            f"none), at most {MAX_SKEW_FRACTION:g} x fx is accepted: give the matrix "
            "'fx 0 cx / 0 fy cy / 0 0 1'")
    return K


def _rational(value) -> float | None:
    try:
        v = float(value)
    except (TypeError, ValueError, ZeroDivisionError):
        return None
    return v if np.isfinite(v) and v > 0 else None


def _exif_int(value) -> int | None:
    """An EXIF SHORT tag as int (2 when absent or 0); None when it is not a number (the tag
    comes from the file and may hold anything, e.g. a string)."""
    try:
        return int(value or 2)
    except (TypeError, ValueError, OverflowError):
        return None


def exif_focal_px(header: Image.Image, width: int, height: int) -> tuple[float, str] | None:
    """Focal length in pixels from EXIF, at the stored ``width x height``, or ``None``.

    Two routes, in this order:

    1. ``FocalLengthIn35mmFilm`` ``f35``: the 35 mm equivalent is defined through the crop
       factor on the diagonal, so ``f = f35 * hypot(w, h) / hypot(36, 24)``.
    2. ``FocalLength`` (mm) times ``FocalPlaneXResolution`` (pixels per unit of
       ``FocalPlaneResolutionUnit``); that resolution refers to ``ExifImageWidth`` pixels, so
       it is rescaled when the stored width differs (the file was resized after capture);
       where the stored image is ``ExifImageWidth x ExifImageHeight`` turned a quarter (pixels
       rotated by a tool that kept the EXIF block), the sensor's width is the stored height.

    Returns
    -------
    (focal_px, source) with source ``exif-35mm`` or ``exif-focal-plane``; ``None`` when
    neither route has usable tags.
    """
    try:
        with warnings.catch_warnings():  # Pillow's "Corrupt EXIF data" lines: the tags it
            warnings.simplefilter("ignore", UserWarning)  # could read serve, or none do
            exif = header.getexif()
            sub = exif.get_ifd(ExifTags.IFD.Exif)
    except Exception:  # noqa: BLE001 - a broken EXIF block just means "no EXIF"
        return None
    tags = {**dict(exif), **dict(sub)}
    f35 = _rational(tags.get(ExifTags.Base.FocalLengthIn35mmFilm))
    if f35 is not None:
        return f35 * float(np.hypot(width, height)) / _FILM_DIAGONAL_MM, "exif-35mm"
    f_mm = _rational(tags.get(ExifTags.Base.FocalLength))
    xres = _rational(tags.get(ExifTags.Base.FocalPlaneXResolution))
    unit_mm = _EXIF_UNIT_MM.get(_exif_int(tags.get(ExifTags.Base.FocalPlaneResolutionUnit, 2)))
    if f_mm is None or xres is None or unit_mm is None:
        return None
    focal = f_mm * xres / unit_mm
    exif_width = _rational(tags.get(ExifTags.Base.ExifImageWidth))
    if exif_width is not None:
        # pixels turned a quarter by a tool that kept the EXIF block: the sensor's width
        # (ExifImageWidth, the axis of FocalPlaneXResolution) is now the stored height
        exif_height = _rational(tags.get(ExifTags.Base.ExifImageHeight))
        turned = exif_height is not None and exif_height != exif_width and width != height \
            and (width > height) != (exif_width > exif_height)
        focal *= (height if turned else width) / exif_width
    return focal, "exif-focal-plane"


def guess_K(width: int, height: int) -> np.ndarray:
    """The stated guess: ``f = 1.2 max(w, h)``, principal point at the image centre."""
    f = GUESS_FOCAL_FACTOR * max(width, height)
    return np.array([[f, 0.0, (width - 1) / 2.0], [0.0, f, (height - 1) / 2.0], [0.0, 0.0, 1.0]])


def _exif_K(header: Image.Image, width: int, height: int) -> tuple[np.ndarray, str] | None:
    found = exif_focal_px(header, width, height)
    if found is None or not focal_px_ok(found[0], width, height):
        return None  # no EXIF focal length, or one no lens has (a corrupt tag)
    f, source = found
    return np.array([[f, 0.0, (width - 1) / 2.0], [0.0, f, (height - 1) / 2.0], [0.0, 0.0, 1.0]]), source


#: names (letter case and spaces aside) that mean K.txt but are not read as it: ``k.txt``
#: written on a file system that ignores case, ``K.txt.txt`` saved by an editor that hides
#: extensions
_K_TXT_LOOKALIKES = ("k.txt", "k.txt.txt")


def warn_misnamed_k_txt(directory: Path,
                        instead: str = "the images' EXIF focal length or the guessed one "
                                       "serve instead") -> None:
    """Warn about what in ``directory`` looks like the intrinsics file but is not read as it:
    ``k.txt``, ``K.TXT``, ``K.txt.txt``, or a ``K.txt`` that is a folder or a link leading
    nowhere. Only a file named exactly ``K.txt`` is read, so the calibration the user put
    there would silently give way to EXIF or the guessed focal length (``instead`` says what
    serves in its place)."""
    try:
        entries = sorted(directory.iterdir(), key=lambda p: p.name)
    except OSError:
        return
    near = [p for p in entries if p.name.strip().casefold() in _K_TXT_LOOKALIKES
            and not (p.name == "K.txt" and p.is_file())]
    for p in near:
        what = ("is not named exactly K.txt (letter case counts)" if p.name != "K.txt"
                else "is a folder" if p.is_dir()
                else "is a symbolic link leading nowhere" if not p.exists()
                else "is not a regular file (a FIFO, device or socket)")
        log.warning("warning: %s", f"{str(p)!r} {what}, so it is not read as the intrinsics "
                    f"file: {instead}; give the intrinsics as a file named exactly K.txt, or "
                    "name the file with --intrinsics")


def _resolve_intrinsics(intrinsics, directory: Path) -> tuple[str, np.ndarray | None, Path | None]:
    """Normalise the ``intrinsics`` argument to (mode, K from file or None, file or None)."""
    if isinstance(intrinsics, Path) or (isinstance(intrinsics, str) and intrinsics not in ("auto", "exif")):
        path = Path(intrinsics)
        return "file", read_k_txt(path), path
    if intrinsics == "exif":
        return "exif", None, None
    if intrinsics == "auto":
        k_file = directory / "K.txt"
        if k_file.is_file():
            return "file", read_k_txt(k_file), k_file
        warn_misnamed_k_txt(directory)
        return "auto", None, None
    raise InputError(f"intrinsics {intrinsics!r}: expected 'auto', 'exif' or the path of a K.txt file")


def _scaled_K(K: np.ndarray, sx: float, sy: float) -> np.ndarray:
    """Intrinsics after resizing by ``(sx, sy)`` in the OpenCV pixel convention (module notes)."""
    S = np.array([[sx, 0.0, 0.5 * sx - 0.5], [0.0, sy, 0.5 * sy - 0.5], [0.0, 0.0, 1.0]])
    return S @ K


def downscale(pixels: np.ndarray, K: np.ndarray, max_size: int | None):
    """The image with its longest side at most ``max_size`` (never upscaled) and its scaled K.

    Returns ``(pixels, K)``; unchanged when ``max_size`` is ``None`` or already met.
    """
    h, w = pixels.shape[:2]
    if max_size is None or max(w, h) <= max_size:
        return pixels, K
    s = max_size / max(w, h)
    nw, nh = max(1, round(w * s)), max(1, round(h * s))
    pixels = cv2.resize(pixels, (nw, nh), interpolation=cv2.INTER_AREA)
    return pixels, _scaled_K(K, nw / w, nh / h)


def pixel_digests(views: list[View]) -> list[bytes]:
    """The SHA-256 digest of each view's pixels (shape and bytes)."""
    import hashlib

    out = []
    for v in views:
        img = np.ascontiguousarray(v.image)
        out.append(hashlib.sha256(repr(img.shape).encode() + img.tobytes()).digest())
    return out


def in_content_order(views: list[View], digests: list[bytes] | None = None) -> list[View]:
    """``views`` sorted by the SHA-256 digest of their pixels (shape and bytes), names last.

    The camera index of a photograph is then a property of what it shows, not of its file
    name: renaming the files of a folder permutes nothing downstream (matching directions,
    the robots' ids of the consistency stage, COLMAP's image ids and its tie-breaks all
    follow the camera index). Two files with identical pixels keep their name order.
    ``digests``: :func:`pixel_digests` of ``views``, when the caller has them.
    """
    digests = pixel_digests(views) if digests is None else digests
    order = sorted(range(len(views)), key=lambda k: (digests[k], views[k].name))
    return [views[k] for k in order]


def identical_pixels(views: list[View], digests: list[bytes] | None = None) -> list[list[str]]:
    """Groups of two or more names of ``views`` whose pixels are identical (as loaded), each
    in name order: the same photograph twice matches itself perfectly and adds nothing.
    ``digests``: :func:`pixel_digests` of ``views``, when the caller has them."""
    groups: dict[bytes, list[str]] = {}
    for v, d in zip(views, pixel_digests(views) if digests is None else digests, strict=True):
        groups.setdefault(d, []).append(v.name)
    return [sorted(g) for g in groups.values() if len(g) > 1]


def load_folder(directory: str | Path, max_size: int | None = 1600,
                intrinsics: str | Path = "auto", check_names=None) -> list[View]:
    """Load every image of a folder as a :class:`View`, in name order.

    Parameters
    ----------
    directory : folder of JPEG / PNG / TIFF images (gray, RGB, RGBA, 8 or 16 bit). Files with
        other suffixes (e.g. ``K.txt``, ``SOURCE.txt``) are skipped; hidden files too.
    max_size : int or None
        Longest image side after downscaling (images are never upscaled); ``None`` keeps the
        full resolution. The intrinsics are scaled with the image.
    intrinsics : ``"auto"``, ``"exif"`` or path of a K.txt
        - path: that ``K`` (at the images' full resolution) for every image; known.
        - ``"exif"``: each image's EXIF focal length (:func:`exif_focal_px`), principal point
          at the centre; known. An image without one is an error.
        - ``"auto"``: ``DIR/K.txt`` if present (as the path case), otherwise per image EXIF if
          present, otherwise the stated guess ``f = 1.2 max(w, h)``, principal point at the
          centre, with ``intrinsics_known=False`` (matching then uses the fundamental matrix).
    check_names : callable or None
        Called with the image file names, in name order, once the folder is listed and before
        any image is decoded (e.g. a comm-graph file naming them, so that a bad row is refused
        before the images of a large folder are read); it raises to refuse them.

    Returns
    -------
    views : list[View], (n,) with n >= 2
        ``image`` (H, W) or (H, W, 3) uint8; ``K`` (3, 3) at the downscaled size; ``R, t`` None.
        ``intrinsics_source`` is ``K.txt``, ``exif-35mm``, ``exif-focal-plane`` or ``guess``.

    Raises
    ------
    InputError
        Missing or empty folder, a single image, a file with an image suffix that cannot be
        decoded (non-image or truncated), a K.txt that does not parse or whose principal point
        lies outside an image, ``intrinsics="exif"`` on an image without EXIF focal length,
        a bad ``max_size``.

    Examples
    --------
    The copy of the Sceaux castle set kept with the tests (11 photographs and their K.txt):

    >>> import pathlib, pipeline
    >>> folder = pathlib.Path(pipeline.__file__).parents[1] / "tests/data/sceaux_castle_640"
    >>> views = load_folder(folder, max_size=320)
    >>> len(views), views[0].size, views[0].intrinsics_source
    (11, (320, 240), 'K.txt')
    """
    directory = Path(directory)
    if max_size is not None:
        if isinstance(max_size, bool) or not isinstance(max_size, (int, np.integer)) or \
                max_size < MIN_MAX_SIZE:
            raise InputError(f"max_size {max_size!r}: expected an integer >= {MIN_MAX_SIZE} (pixels of the "
                             f"longest side), or None for full resolution")
    files = _image_files(directory)
    mode, K_file, k_path = _resolve_intrinsics(intrinsics, directory)
    if check_names is not None:
        check_names([p.name for p in files])
    views: list[View] = []
    multi: list[str] = []
    off_centre: list[str] = []
    turned: list[str] = []  # portrait files beside a landscape K.txt, or the other way round
    for path in files:
        pixels, header = load_image(path)
        # a multi-page TIFF, an animated PNG or WebP: the frames after the first are not
        # read; a camera's MPO JPEG (a preview or depth map after the photo) is not warned
        frames = getattr(header, "n_frames", 1)
        if isinstance(frames, int) and frames > 1 and header.format != "MPO":
            multi.append(f"{path.name} ({frames})")
        h, w = pixels.shape[:2]
        if mode == "file":
            K, source, known = K_file, "K.txt", True
            cx, cy = K[0, 2], K[1, 2]
            check_focal(K, w, h, str(k_path), path.name)
            if not (0 <= cx <= w and 0 <= cy <= h):
                raise InputError(
                    f"{k_path}: principal point ({cx:g}, {cy:g}) lies outside image {path.name} "
                    f"({w}x{h}); K.txt must be given at the images' full resolution")
            # how far the principal point lies from the centre, as a fraction of the side,
            # in the image as stored and in the image turned a quarter (h x w)
            off = max(abs(cx - (w - 1) / 2) / w, abs(cy - (h - 1) / 2) / h)
            off_turned = max(abs(cx - (h - 1) / 2) / h, abs(cy - (w - 1) / 2) / w)
            if w != h and off_turned <= OFF_CENTRE and off_turned < off:
                turned.append(f"{path.name} ({w}x{h})")
            elif off > OFF_CENTRE:
                off_centre.append(f"{path.name} ({w}x{h})")
        else:
            found = _exif_K(header, w, h)
            if found is not None:
                (K, source), known = found, True
            elif mode == "exif":
                raise InputError(
                    f"{path}: no EXIF focal length (FocalLengthIn35mmFilm, or FocalLength "
                    f"with FocalPlaneXResolution); use --intrinsics auto (guess) or a K.txt")
            else:
                K, source, known = guess_K(w, h), "guess", False
        header.close()
        pixels, K = downscale(pixels, K, max_size)
        views.append(View(name=path.name, image=pixels, K=np.array(K, dtype=np.float64),
                          intrinsics_known=known, intrinsics_source=source))
    if off_centre:
        cx, cy = K_file[0, 2], K_file[1, 2]
        log.warning("warning: %s", f"{k_path}: principal point ({cx:g}, {cy:g}) lies far from "
                    f"the centre of {len(off_centre)} image(s): {', '.join(off_centre[:5])}"
                    f"{', ...' if len(off_centre) > 5 else ''}; is K.txt for another "
                    "resolution? It must be at the files' resolution (for resized copies, scale "
                    "fx, fy, cx and cy by the resize factor)")
    if turned:
        cx, cy = K_file[0, 2], K_file[1, 2]
        log.warning("warning: %s", f"{k_path}: principal point ({cx:g}, {cy:g}) lies near the "
                    "centre of the image turned a quarter, not of the image, for "
                    f"{len(turned)} image(s): {', '.join(turned[:5])}"
                    f"{', ...' if len(turned) > 5 else ''}; their pixels are turned against "
                    "K.txt's camera (one K serves every image, and the EXIF orientation tag "
                    "is not applied): turn those files to K.txt's orientation, or run them "
                    "apart with a K.txt of their own (fx, fy and cx, cy swapped)")
    if multi:
        log.warning("warning: %s", f"{len(multi)} file(s) in {str(directory)!r} hold several "
                    f"frames or pages and only the first of each is read: {', '.join(multi)}; "
                    "save each frame as its own image file to use it")
    log.info("loaded %d images from %s (intrinsics: %s)", len(views), directory,
             ", ".join(sorted({v.intrinsics_source for v in views})))
    return views
