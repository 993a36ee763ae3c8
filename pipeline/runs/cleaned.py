"""What the cleaning commands (``clean-db``, ``clean-h5``) cut, and why, as files a user opens.

Both commands make another tool's matches consistent (Aragüés et al., Sec. III detection and
Sec. IV Alg. 1 resolution, one robot per image) and write the cleaned matches in that tool's
format. Beside them they write, with the same stem:

- ``STEM.links.csv`` — the run-output ``links.csv`` (docs/DESIGN.md "Run outputs"): every link read,
  ``kept`` or ``deleted`` with its reason (``not-one-to-one``, ``not-comm-edge``,
  ``loop-inconsistent``, ``resolution``) and the resolution round that cut it; camera ``i`` is the ``i``-th image name
  in sorted order. ``resolve --links STEM.links.csv`` reads it back.
- ``STEM.rrd`` — a Rerun recording: each image (from ``--image-dir``, else a gray canvas of the
  camera's size) with its keypoints coloured by status, the conflict graph, the report. The
  cameras have no pose (the input holds none), so they are drawn as images only.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.errors import InputError
from pipeline.types import Features, LinkLedger, Links, View

__all__ = ["side_paths", "CleaningOutcome", "cleaning_ledger", "image_file", "check_image_dir",
           "write_side_outputs", "stale_recording"]


def side_paths(out: str | Path) -> tuple[Path, Path]:
    """``(STEM.links.csv, STEM.rrd)`` beside the cleaned file ``out``."""
    out = Path(out)
    stem = out.with_suffix("") if out.suffix else out
    return stem.with_name(stem.name + ".links.csv"), stem.with_name(stem.name + ".rrd")


def stale_recording(out: str | Path) -> str | None:
    """The warning for an ``OUT.rrd`` beside ``out`` after a run with ``--no-rerun``, which
    writes none: that recording is of an earlier run (or not ours) and does not show this
    result, though it is named like its recording; ``None`` when there is no such file."""
    rrd = side_paths(out)[1]
    if not os.path.lexists(rrd):
        return None
    return (f"warning: {str(rrd)!r} beside {str(out)!r} is not this run's recording "
            f"(--no-rerun writes none): it does not show this result; remove it, or run "
            f"without --no-rerun")


@dataclass
class CleaningOutcome:
    """What a cleaning command read and decided: the images (names, sizes, keypoints) and the
    per-link record of every link read (:class:`~pipeline.types.LinkLedger`)."""

    names: list[str]
    sizes: list[tuple[int, int]]
    keypoints: list[np.ndarray]
    ledger: LinkLedger


def cleaning_ledger(links: Links, reason: np.ndarray, rows: np.ndarray, result,
                    model_links: Links, features_per_camera) -> LinkLedger:
    """The ledger of a cleaning command: the links an earlier check cut (``reason`` not
    empty, e.g. ``not-one-to-one``), then the consistency stage's decisions (``result`` on
    ``model_links``, the links ``rows``) with each link's place in a conflictive set before,
    then the links a later stage cut among those it kept (``fusion-outlier``)."""
    from pipeline.association import conflictive_links
    from pipeline.stages import ledger_from_consistency

    reason = np.asarray(reason, dtype=str)
    ledger = LinkLedger.all_kept(links)
    for why in sorted(set(reason) - {"", "resolution", "fusion-outlier"}):
        ledger.cut(reason == why, why, -1)
    ledger.place(rows, ledger_from_consistency(
        result, conflictive_links(features_per_camera, model_links)))
    if (reason == "fusion-outlier").any():
        ledger.cut(reason == "fusion-outlier", "fusion-outlier", -1)
    return ledger


def image_file(image_dir: Path, name: str) -> Path | None:
    """The file of ``image_dir`` holding the image ``name`` (a path relative to it), or
    ``None``. A name whose accents the database or features file encodes otherwise than the
    file system (decomposed, NFD, as macOS wrote it; composed, NFC, as an archive unpacked
    elsewhere did) finds its file where exactly one file of that folder has the same NFC
    form: "no image 'château.jpg' in it" named a file the folder visibly held."""
    import unicodedata

    path = image_dir / name
    if path.is_file():
        return path
    want = unicodedata.normalize("NFC", path.name)
    try:
        same = [p for p in path.parent.iterdir()
                if unicodedata.normalize("NFC", p.name) == want and p.is_file()]
    except OSError:  # no such sub-folder (or one that cannot be listed)
        return None
    return same[0] if len(same) == 1 else None


def check_image_dir(image_dir: str | Path | None, names: list[str],
                    sizes: list[tuple[int, int]] | None = None, of: str = "",
                    oriented: bool = False) -> None:
    """InputError unless ``image_dir`` (when given) is a folder holding every image of
    ``names``; checked before any work, so that nothing is written for a run that cannot
    finish.

    ``sizes``: the ``(width, height)`` each image's keypoints are in (``(0, 0)``: unknown),
    ``of`` where they come from (``the camera of the database``). An image of ``image_dir``
    must be that image, or it scaled alike on both axes (the recording scales the keypoints
    to it): one of another shape (turned a quarter since it was matched, another photograph
    of that name) would have its keypoints drawn stretched over the wrong pixels. Only the
    headers are read. ``oriented``: the tool read each image turned by its EXIF orientation
    tag (:func:`write_side_outputs`)."""
    if image_dir is None:
        return
    d = Path(image_dir)
    if not d.is_dir():
        raise InputError(f"--image-dir {str(image_dir)!r} is not a folder; give the folder of "
                         "the images (or leave it out: gray canvases are drawn)")
    missing = [n for n in names if image_file(d, n) is None]
    if missing:
        raise InputError(f"--image-dir {str(image_dir)!r}: no image {missing[0]!r} in it"
                         + (f" (nor {len(missing) - 1} other(s))" if len(missing) > 1 else "")
                         + "; give the folder the images were matched from, or leave "
                         "--image-dir out (gray canvases are drawn)")
    for name, (w, h) in zip(names, sizes if sizes is not None else [(0, 0)] * len(names),
                            strict=True):
        if w > 0 and h > 0:
            _check_same_shape(image_file(d, name), name, (w, h), of, str(image_dir), oriented)


def _check_same_shape(path: Path, name: str, size: tuple[int, int], of: str,
                      image_dir: str, oriented: bool) -> None:
    """InputError when the image file ``path`` is not the ``size`` image its keypoints are
    in, scaled alike on both axes (:func:`check_image_dir`)."""
    from PIL import UnidentifiedImageError

    from pipeline.inputs.photos import exif_orientation, load_image, open_header

    try:
        with open_header(path) as im:
            iw, ih = im.size
            if oriented and exif_orientation(im) >= 5:  # a quarter turn
                iw, ih = ih, iw
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError):
        load_image(path)  # its InputError names what is wrong with the file
        raise
    w, h = size
    # a resize rounds each side to a whole pixel: |ih w - iw h| <= (w + h) / 2
    if abs(ih * w - iw * h) > (w + h) / 2:
        turned = abs(iw * w - ih * h) <= (w + h) / 2
        raise InputError(
            f"--image-dir {image_dir!r}: {name!r} is {iw}x{ih}, but its keypoints are in a "
            f"{w}x{h} image ({of}), and it is not that image scaled"
            + (" (it is that image turned a quarter: its pixels were rotated since it was "
               "matched)" if turned else "")
            + "; give the folder the images were matched from, or leave --image-dir out "
            "(gray canvases are drawn)")


def _load_view(name: str, size: tuple[int, int], image_dir: Path | None,
               oriented: bool = False) -> View:
    w, h = (max(int(size[0]), 1), max(int(size[1]), 1))
    image = None
    if image_dir is not None:
        from pipeline.inputs.photos import as_oriented, exif_orientation, load_image

        path = image_file(image_dir, name)
        if path is None:
            raise InputError(f"--image-dir {str(image_dir)!r}: no image {name!r} in it")
        image, header = load_image(path)
        if oriented:
            image = as_oriented(image, exif_orientation(header))
        header.close()
    if image is None:
        image = np.full((h, w), 96, dtype=np.uint8)
    ih, iw = image.shape[:2]
    f = 1.2 * max(iw, ih)
    K = np.array([[f, 0.0, (iw - 1) / 2.0], [0.0, f, (ih - 1) / 2.0], [0.0, 0.0, 1.0]])
    return View(name=name, image=image, K=K, intrinsics_known=False)


def write_side_outputs(outcome: CleaningOutcome, out: str | Path, *, rerun: bool = True,
                       image_dir: str | Path | None = None, report_markdown: str = "",
                       outputs=None, oriented: bool = False) -> list[Path]:
    """Write ``STEM.links.csv`` and (with ``rerun``) ``STEM.rrd`` beside ``out``.

    Returns the paths written. Keypoints read from another tool are scaled to the images of
    ``image_dir`` when those differ in size from the stored camera size. ``outputs``: a
    :class:`pipeline.runfolder.OutputFiles` that puts them in place with the command's other
    outputs (default: written at once). ``oriented``: the tool read each image of
    ``image_dir`` turned by its EXIF orientation tag, as hloc does (its ``read_image`` is
    OpenCV's ``imread``, which applies the tag), so its keypoints are in the pixels so turned
    and the image is drawn so; COLMAP reads the pixels as stored (clean-db), as run-images
    does.
    """
    from pipeline.inputs.linkscsv import write_links_csv
    from pipeline.runfolder import output_path

    links_csv, rrd = side_paths(out)
    ledger = outcome.ledger
    write_links_csv(output_path(outputs, links_csv, "OUT.links.csv"), ledger)
    written = [links_csv]
    if rerun:
        from pipeline.types import RunRecord
        from viz.rerun_log import log_run

        image_dir = Path(image_dir) if image_dir is not None else None
        views, feats = [], []
        for name, size, kp in zip(outcome.names, outcome.sizes, outcome.keypoints, strict=True):
            v = _load_view(name, size, image_dir, oriented)
            kp = np.asarray(kp, dtype=np.float32).reshape(-1, 2)
            if image_dir is not None and size[0] > 0 and v.size != tuple(size):
                s = np.array([v.size[0] / size[0], v.size[1] / size[1]], np.float32)
                kp = (kp + 0.5) * s - 0.5
            views.append(v)
            feats.append(Features(kp, np.zeros((len(kp), 0), np.float32),
                                  np.ones(len(kp), np.float32), "external"))
        record = RunRecord(
            views=views, features=feats, ledger=ledger, points=np.zeros((0, 3)),
            point_tracks=np.zeros(0, dtype=np.int64), report_markdown=report_markdown)
        log_run(output_path(outputs, rrd, "OUT.rrd"), record)
        written.append(rrd)
    return written
