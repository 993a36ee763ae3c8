"""Log a saved run folder to Rerun: ``python -m viz.saved_run RUN_DIR [--out FILE.rrd]``.

Reads what a run wrote (docs/DESIGN.md "Run outputs": ``links.csv``, ``report.json``, ``sparse/``)
back into a :class:`~pipeline.types.RunRecord` and logs it with :func:`viz.rerun_log.log_run`,
e.g. for a run made with ``--no-rerun``. The conflictive sets before the resolution are those
of every link ``links.csv`` lists (every link matching produced, kept or cut:
:func:`pipeline.association.conflictive_links`, as the run computed them); nothing else is
computed, and what the folder does not hold is left out of the recording:

- the images (not in a run folder): each camera shows a blank image of its size;
- the iteration of each cut (not in ``links.csv``): the replay orders cuts by round only;
- how the rule decided each cut (Alg. 1's case, the evidence rule, the ``sync`` merge; not in
  ``links.csv``): the cuts panel and the labels name the stage (``resolution``) only;
- cameras absent from ``sparse/`` (an image the mapper did not register): drawn without a
  pose, their keypoints unknown;
- ground-truth and fused points.
"""

from __future__ import annotations

if __name__ == "__main__":  # run as a program: a Ctrl-C while the libraries load is one line
    from pipeline.errors import exit_quietly_on_interrupt

    exit_quietly_on_interrupt("viz.saved_run")

import argparse  # noqa: E402
import contextlib  # noqa: E402
import json  # noqa: E402
import os  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from pipeline.errors import InputError  # noqa: E402
from pipeline.types import Features, RunRecord, View  # noqa: E402
from viz.view import say  # noqa: E402

__all__ = ["read_run_folder", "log_run_folder", "main"]


def _camera_names(report: dict, images: dict) -> list[str]:
    """Camera ``i``'s image name: from the report of a photo run, else (rendered formations,
    whose ``sparse/`` holds every camera with image id ``i + 1``) in image-id order."""
    if "images" in report:
        return [im["name"] for im in report["images"]]
    return [name for name, _ in sorted(images.items(), key=lambda kv: kv[1]["image_id"])]


def _check_report_images(folder: Path, report: dict) -> None:
    """InputError unless ``report.json``'s ``images`` (a photo run's; absent in a formation
    run's) lists, per camera, its ``name``, its ``size`` ``[width, height]`` in pixels and its
    3 x 3 ``K``: what the recording reads of an image the mapper did not register."""
    if "images" not in report:
        return
    images = report["images"]
    bad = None if isinstance(images, list) else f"is {str(images)[:60]!r}, not a list"
    for k, im in enumerate(images if bad is None else ()):
        if not isinstance(im, dict):
            bad = f"entry {k} is {str(im)[:60]!r}, not an object"
        elif not isinstance(im.get("name"), str) or not im["name"]:
            bad = f"entry {k} has no image name ({str(im.get('name'))[:60]!r})"
        elif not (isinstance(im.get("size"), list) and len(im["size"]) == 2 and all(
                isinstance(x, int) and not isinstance(x, bool) and x > 0 for x in im["size"])):
            bad = (f"entry {k} ({im['name']}) has size {str(im.get('size'))[:60]!r}, not "
                   "[width, height] in pixels")
        elif not _is_matrix_3x3(im.get("K")):
            bad = (f"entry {k} ({im['name']}) has K {str(im.get('K'))[:60]!r}, not an "
                   "invertible 3 x 3 camera matrix")
        if bad:
            break
    if bad:
        raise InputError(f"{folder}: report.json's images {bad}; not a run's report "
                         "(docs/DESIGN.md 'Run outputs')")


def _is_matrix_3x3(K) -> bool:
    """Whether ``K`` is a camera matrix: 3 x 3 finite numbers, invertible (the recording
    back-projects keypoints through its inverse)."""
    return isinstance(K, list) and len(K) == 3 and all(
        isinstance(row, list) and len(row) == 3 and all(
            isinstance(x, int | float) and not isinstance(x, bool) and np.isfinite(x) for x in row)
        for row in K) and np.linalg.cond(np.asarray(K, float)) < 1e12


def _feature_counts(folder: Path, report: dict) -> list[int]:
    """``report.json``'s ``features_per_camera``: one whole count >= 0 per camera, else an
    InputError naming the value."""
    m = report["features_per_camera"]
    if not isinstance(m, list) or not all(
            isinstance(x, int) and not isinstance(x, bool) and x >= 0 for x in m):
        raise InputError(f"{folder}: report.json's features_per_camera is {str(m)[:80]!r}, not "
                         "a list of feature counts (whole numbers >= 0, one per camera); not a "
                         "run's report (docs/DESIGN.md 'Run outputs')")
    return m


def _refuse_online(folder: Path) -> None:
    """InputError for an online run folder: its recording comes from the run only."""
    if not ((folder / "link_steps.csv").exists() and (folder / "images.csv").exists()):
        return
    what = (f"its recording, on the step timeline, is {folder / 'recording.rrd'}, written by "
            "the run itself: open it with make view RUN=" + str(folder)
            if (folder / "recording.rrd").is_file() else
            "its recording, on the step timeline, is written by the run itself from what it "
            "holds in memory; run it again without --no-rerun")
    raise InputError(f"{folder}: an online run folder (run-formation --steps, run-images "
                     f"--sequence): {what}")


def _check_is_folder(folder: Path) -> None:
    """InputError unless ``folder`` is a folder (or a symbolic link to one), naming what it is."""
    from pipeline.inputs.photos import why_missing

    if folder.is_dir():
        return
    if folder.exists():
        what = ": a file, not a folder"
    else:  # a symbolic link leading nowhere, it or one on its way, is named with its target
        why = why_missing(folder)
        what = ": no such folder" if why == "does not exist" else f" {why}"
    raise InputError(f"{folder}{what}; give the run folder (--out) of a run-formation or "
                     "run-images run")


def _what_instead(folder: Path) -> str:
    """What to give for a folder that is no run folder: the runs it holds (``run-formations``'
    --out), or the recordings ``clean-db`` / ``clean-h5`` wrote in it (``OUT.rrd``)."""
    import shlex

    from pipeline.progress import counted
    from viz.view import names_shown

    runs = sorted(q.parent for q in folder.glob("*/report.json")
                  if not q.parent.name.startswith("."))
    if runs:
        return f"; a folder of {counted(len(runs), 'run')} ({names_shown(runs)}): give one of them"
    rrds = sorted(q for q in folder.glob("*.rrd") if not q.name.startswith("."))
    if rrds:
        return (f"; it holds {counted(len(rrds), 'recording')} already ({names_shown(rrds)}, as "
                "clean-db and clean-h5 write beside their output): open it with make view "
                f"RUN={shlex.quote(str(rrds[0]))}")
    return ""


def read_run_folder(folder: str | Path) -> RunRecord:
    """The :class:`RunRecord` of a saved run folder (see the module docstring for what a
    folder does not hold).

    Raises
    ------
    InputError
        A missing ``report.json``, ``links.csv`` or ``sparse/``, one that does not read
        (``report.json`` not JSON, without ``features_per_camera`` or with ``images`` entries
        lacking a name, a size or an invertible 3 x 3 ``K``; ``sparse/`` without a COLMAP
        model), or files that disagree (a camera count different from the report's).
    """
    from pipeline import colmap
    from pipeline.inputs.linkscsv import read_run_links_csv
    from pipeline.inputs.photos import MAX_IMAGE_PIXELS
    from viz.view import LANDMARKS_RUN_NOTE, landmarks_run, staging_note

    folder = Path(folder)
    _check_is_folder(folder)
    if landmarks_run(folder):
        raise InputError(f"{folder}: {LANDMARKS_RUN_NOTE}")
    staging = staging_note(folder)
    if staging:
        raise InputError(f"{folder}: {staging}")
    _refuse_online(folder)
    for name in ("report.json", "links.csv", "sparse"):
        if not (folder / name).exists():
            raise InputError(f"{folder}: no {name}; not a run folder (docs/DESIGN.md 'Run "
                             f"outputs'){_what_instead(folder)}")
        if (folder / name).is_file() != (name != "sparse"):  # a FIFO would block the read
            what = "a folder" if name == "sparse" else "a regular file"
            raise InputError(f"{folder}: its {name} is not {what}; not a run folder "
                             "(docs/DESIGN.md 'Run outputs')")
    from pipeline.association import conflictive_links

    try:
        report = json.loads((folder / "report.json").read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{folder}: report.json is not a run's report (not JSON: {exc})") \
            from exc
    if not isinstance(report, dict) or "features_per_camera" not in report:
        raise InputError(f"{folder}: report.json lists no features_per_camera; not a run's "
                         "report (docs/DESIGN.md 'Run outputs')")
    ledger = read_run_links_csv(folder / "links.csv")
    try:
        rec = colmap.read_model(folder / "sparse")
    except ValueError as exc:  # pycolmap: missing or unreadable model files
        raise InputError(f"{folder}: sparse/ holds no readable COLMAP model ({exc})") from exc
    images = colmap.model_images(rec)
    m = _feature_counts(folder, report)
    _check_report_images(folder, report)
    names = _camera_names(report, images)
    if len(names) != len(m):
        raise InputError(f"{folder}: report.json lists {len(m)} cameras but {len(names)} images "
                         "are known; the folder's files do not belong together")
    config = report.get("config")
    method = str(config.get("features", "")) if isinstance(config, dict) else ""
    views, feats = [], []
    for k, name in enumerate(names):
        im = images.get(name)
        if im is not None:
            size, K, R, t, kp = im["size"], im["K"], im["R"], im["t"], im["keypoints"]
        else:
            meta = report["images"][k]
            size, K, R, t = tuple(meta["size"]), np.asarray(meta["K"], float), None, None
            kp = None  # unknown: as many as report.json counts, checked below
        if int(size[0]) * int(size[1]) > MAX_IMAGE_PIXELS:  # its blank image would not fit
            raise InputError(f"{folder}: camera {k} ({name}) is {size[0]} x {size[1]} pixels "
                             f"in {'sparse/' if im is not None else 'report.json'}, more than "
                             f"any image a run reads ({MAX_IMAGE_PIXELS:,} pixels); the "
                             "folder's files are not a run's")
        if kp is None and m[k] > int(size[0]) * int(size[1]):  # nor would its keypoints
            raise InputError(f"{folder}: camera {k} ({name}) has {m[k]:,} features in "
                             f"report.json, more than its {size[0]} x {size[1]} pixels; the "
                             "folder's files are not a run's")
        kp = np.full((m[k], 2), np.nan) if kp is None else kp
        if len(kp) != m[k]:
            raise InputError(f"{folder}: camera {k} ({name}) has {len(kp)} keypoints in sparse/ "
                             f"but {m[k]} features in report.json")
        views.append(View(name=name, image=np.full((size[1], size[0]), 128, np.uint8), K=K,
                          R=R, t=t))
        feats.append(Features(kp.astype(np.float32), np.zeros((m[k], 0), np.float32),
                              np.ones(m[k], np.float32), method))
    try:
        ledger.conflictive_before = conflictive_links(m, ledger.links)
    except InputError as exc:  # a link naming a camera or feature report.json does not list
        raise InputError(f"{folder / 'links.csv'}: {exc}; the folder's links.csv and "
                         "report.json do not belong together") from None
    points, point_ids, _, _ = colmap.model_points(rec)
    return RunRecord(views=views, features=feats, ledger=ledger, points=points,
                     point_tracks=point_ids, report_markdown=_markdown(report))


def _markdown(report: dict) -> str:
    from pipeline.evaluation.report import images_report_markdown, report_markdown

    if not (all(isinstance(report.get(k), dict) for k in ("before", "after", "resolution"))
            and all(isinstance(report.get(k) or {}, dict) for k in ("fusion", "faults"))):
        return ""  # a report without those sections as objects: no report panel
    try:  # a photo run's report: its reconstructions and warnings too, as the run shows it
        return images_report_markdown(report) if "images" in report else report_markdown(report)
    except KeyError:  # a report whose sections lack a figure of the table
        return ""


def log_run_folder(folder: str | Path, out: str | Path | None = None) -> Path:
    """Write the Rerun recording of a saved run folder; return its path.

    ``out`` defaults to ``folder/recording.rrd`` when the folder has none (a run made with
    ``--no-rerun``); an existing recording is never replaced unless named as ``out``. A
    recording written into a run folder that held only what its run wrote is added to the
    folder's marker, so that a next run may still replace the folder
    (:func:`pipeline.outputs.run_folder_problem`).
    """
    from pipeline.outputs import check_output_files, run_folder_problem, write_run_marker
    from pipeline.runfolder import note_output_in_place, reading_run_folder, staging_beside
    from pipeline.validate import not_empty
    from viz.rerun_log import log_run
    from viz.view import staging_note

    not_empty(folder, "RUN_DIR", "give the run folder (a run's --out)")  # not the current one
    not_empty(out, "--out", "name a .rrd file, or drop --out to write RUN_DIR/recording.rrd")
    folder = Path(folder)
    _check_is_folder(folder)  # before the output's checks, which would name the recording
    staging = staging_note(folder)
    if staging:  # before a lock is taken beside it, or a recording written into it
        raise InputError(f"{folder}: {staging}")
    _refuse_online(folder)  # before the output: its recording.rrd is the one to open
    named = out is not None
    if out is None:
        out = folder / "recording.rrd"
        if out.exists():
            raise InputError(f"{out} exists; name another file with --out")
    out = Path(out)
    if out.suffix != ".rrd":
        raise InputError(f"--out {str(out)!r}: a recording is written to a .rrd file; name one "
                         "(e.g. recording.rrd)")
    if out.is_symlink() or (out.exists() and not out.is_file()):
        raise InputError(f"--out {str(out)!r} is not a regular file; name a .rrd file")
    try:  # before any work: a read-only folder refused the temporary file with a traceback
        check_output_files([("--out" if named else "the recording", out)], overwrite=True)
    except InputError as exc:
        if not named:
            raise InputError(f"{exc} with --out FILE.rrd") from None
        raise
    # a run replacing the folder meanwhile would mix two runs' files, or get a recording of
    # the previous run added to its own: no run takes the folder while it is read and written
    with reading_run_folder(folder) as real:
        inside = Path(out).resolve().parent == real
        pure_run = inside and run_folder_problem(folder) is None
        record = read_run_folder(folder)
        # written beside the folder, then renamed into it: a recording's temporary file left
        # in the folder by a kill would keep every later run from replacing it
        with staging_beside(real) if inside else contextlib.nullcontext() as stage:
            path = log_run(out if stage is None else stage / out.name, record,
                           recording_name=folder.name)
            if stage is not None:
                os.replace(path, out)
                path = out
        note_output_in_place(path)  # a Ctrl-C from here on names it as written
        if pure_run:
            write_run_marker(folder, finished=True)
    return path


def main(argv: list[str] | None = None) -> int:
    """The program: exit code 0 written, 2 bad input, 130 interrupted (Ctrl-C: one line on
    stderr, as the pipeline's commands say it; the recording is written to a temporary
    sibling and renamed, so none is half-written)."""
    from pipeline.__main__ import interruptible

    return interruptible("viz.saved_run", lambda: _main(argv))


def _main(argv: list[str] | None) -> int:
    ap = argparse.ArgumentParser(prog="python -m viz.saved_run",
                                 description="Log a saved run folder to a Rerun recording.")
    ap.add_argument("folder", metavar="RUN_DIR", help="run folder (report.json, links.csv, sparse/)")
    ap.add_argument("--out", default=None, metavar="FILE.rrd",
                    help="recording to write (default RUN_DIR/recording.rrd if it has none)")
    args = ap.parse_args(argv)
    try:
        path = log_run_folder(args.folder, args.out)
    except (InputError, FileNotFoundError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    say(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
