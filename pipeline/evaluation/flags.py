"""Warnings a photo run must not keep to itself: a weak reconstruction, and cleaning that hurt.

:func:`reconstruction_flags` compares the reconstruction before cleaning (all links) with the
one after (kept links) and looks at what matching produced, and returns one flag per problem,
each with a likely cause that names what to try. The runner puts them in ``report.json``
(``flags``), in the markdown report and on stderr.

Flags
-----
``few-registered``
    The reconstruction before cleaning registered fewer than half the images.
``unregistered``
    It registered half of them or more, but not all: the images it left out are named, and
    those another model of COLMAP's held (``sparse/`` keeps the largest model only).
``relaxed-registration``
    COLMAP's registration threshold left images out and the reconstruction before cleaning
    is the one mapped again at the relaxed threshold
    (:func:`pipeline.colmap.incremental_mapping_with_retry`).
``images-lost``
    Cleaning lost images: registered after < registered before.
``bogus-cameras``
    Registered images of the reconstruction after cleaning (``sparse/``) have camera
    parameters COLMAP's own mapper deems bogus (focal length ratio outside ``[0.1, 10]``, a
    distortion term above 1): their poses and points are not to be trusted.
``cleaning-worse``
    Cleaning made another figure worse by more than 5 %: fewer points (unless the mean
    reprojection error fell and the tracks stayed as long: then the points that went were the
    inconsistent ones), a shorter mean track, or a larger mean reprojection error.
"""

from __future__ import annotations

import numpy as np

from pipeline.commgraph import graph_parts

__all__ = ["reconstruction_flags", "flags_markdown"]

#: relative change of points / reprojection error below which cleaning is not flagged
TOLERANCE = 0.05


def _weak_matching_causes(n: int, edges: np.ndarray, pair_links: list[int],
                          features_per_camera: list[int], intrinsics_guessed: int) -> list[str]:
    m = np.asarray(features_per_camera, dtype=np.int64)
    if len(m) and not m.any():
        # nothing reached matching: the ratio and epipolar tests had no match to reject
        return [f"no image has any feature (the detector found none in the {len(m)} images): "
                f"they are too small or too plain for it; use larger or more textured images "
                f"(a larger --max-size if they were downscaled), or another --features, e.g. "
                f"sift"]
    causes = []
    parts = graph_parts(n, edges)
    if parts > 1:
        causes.append(f"the comm graph splits the {n} images into {parts} groups that never "
                      f"match each other (choose a denser --graph, e.g. complete or knn:K "
                      f"with a larger K)")
    links = np.asarray(pair_links, dtype=np.int64)
    if len(links):
        empty = int((links == 0).sum())
        if empty > len(links) / 2:
            causes.append(f"{empty} of {len(links)} image pairs got no association (too few "
                          f"matches survived the ratio and epipolar tests): the images overlap "
                          f"little or have too few features (try --max-features 8192 or a "
                          f"larger --max-size)")
    if len(m) and int(np.median(m)) < 1000:
        causes.append(f"few features per image (median {int(np.median(m))}): textureless or "
                      f"small images (try a larger --max-size or --max-features)")
    if intrinsics_guessed:
        causes.append(f"{intrinsics_guessed} image(s) without known intrinsics (focal length "
                      f"guessed): add a K.txt to the folder or use photos with EXIF")
    return causes or ["the images may not show one common scene"]


def reconstruction_flags(n_images: int, before: dict, after: dict, comm_edges,
                         pair_links: list[int], features_per_camera: list[int],
                         intrinsics_guessed: int = 0, cut_by_reason: dict | None = None,
                         lost_image_cuts: dict | None = None,
                         image_names: list[str] | None = None) -> list[dict]:
    """Flags of a photo run (module notes).

    Parameters
    ----------
    n_images : int
    before, after : dict — :meth:`pipeline.colmap.MappingSummary.summary` of the
        reconstruction before / after cleaning (``registered_images``, ``registered_names``,
        ``points``, ``mean_track_length``, ``mean_reprojection_error``)
    comm_edges : (E, 2) int — the comm graph
    pair_links : list[int], (E,) — links matching produced per comm edge
    features_per_camera : list[int], (n,)
    intrinsics_guessed : int — images whose focal length was guessed
    cut_by_reason : dict — links cut per reason (``resolution``, ``fusion-outlier``…)
    lost_image_cuts : dict — for each image lost by cleaning, ``{reason: links cut}`` of its
        links
    image_names : list[str], (n,) — every image's name (to name the unregistered ones); with
        ``before["other_models"]`` (the registered images of COLMAP's other models)

    Returns
    -------
    list of dict — ``{"flag", "message", "likely_cause"}``, empty when nothing is wrong
    """
    flags = []
    reg_b, reg_a = int(before["registered_images"]), int(after["registered_images"])
    if reg_b < n_images / 2:
        causes = _weak_matching_causes(n_images, np.asarray(comm_edges), pair_links,
                                       features_per_camera, intrinsics_guessed)
        if before.get("models") == 0 and max(pair_links, default=0) > 0:
            # COLMAP's mapper starts from one image pair: IncrementalMapperOptions'
            # init_min_num_inliers (100) and init_min_tri_angle (16 degrees)
            causes.insert(0, f"COLMAP found no image pair to start its model from, though "
                             f"matching linked up to {max(pair_links)} features of a pair: "
                             f"a first pair needs 100 inliers seen with 16 degrees of "
                             f"triangulation angle (photos taken from nearly one place, or "
                             f"too few photos, give it none)")
        flags.append({"flag": "few-registered",
                      "message": f"the reconstruction registered only {reg_b} of {n_images} "
                                 f"images (fewer than half){_other_models(before)}",
                      "likely_cause": "; ".join(causes)})
    elif reg_b < n_images:
        left = sorted(set(image_names or []) - set(before.get("registered_names", [])))
        named = f": {_few(left)}" if left else ""
        flags.append({"flag": "unregistered",
                      "message": f"the reconstruction left {n_images - reg_b} of {n_images} "
                                 f"images unregistered{named}{_other_models(before)}",
                      "likely_cause": "they share too few matches with the registered images "
                                      "(another scene, little overlap, or views from nearly "
                                      "one place: a model grows only through points it has "
                                      "triangulated); run them as a folder of their own, or "
                                      "add photos that link them to the others"})
    if before.get("registered_at_colmap_default") is not None:
        flags.append({"flag": "relaxed-registration",
                      "message": f"COLMAP's registration threshold (30 triangulated points "
                                 f"seen) registered {before['registered_at_colmap_default']} of "
                                 f"{n_images} images; at {before['min_pose_inliers']} points "
                                 f"{reg_b} were registered",
                      "likely_cause": "a weak view graph: few matches reach the images the "
                                      "first model lacked; their poses rest on fewer points "
                                      "(check them, or add photos that overlap them)"})
    bogus = list(after.get("bogus_camera_images", []))
    if bogus:
        flags.append({"flag": "bogus-cameras",
                      "message": f"COLMAP deems the camera parameters of {len(bogus)} "
                                 f"registered image(s) of sparse/ bogus (focal length ratio "
                                 f"outside [0.1, 10] or a distortion term above 1): "
                                 f"{', '.join(bogus[:5])}{', ...' if len(bogus) > 5 else ''}",
                      "likely_cause": "intrinsics that the photos cannot pin down (few or small "
                                      "images, a guessed focal length refined on weak "
                                      "geometry): give a K.txt, use photos with EXIF, or a "
                                      "larger --max-size"})
    cut = {k: int(v) for k, v in (cut_by_reason or {}).items() if v}
    cut_text = ", ".join(f"{v} by {k}" for k, v in sorted(cut.items())) or "none"
    if reg_a < reg_b:
        lost = sorted(set(before.get("registered_names", [])) - set(after.get("registered_names", [])))
        per = lost_image_cuts or {}
        detail = "; ".join(
            f"{name}: " + (", ".join(f"{v} links cut by {k}" for k, v in sorted(per[name].items()))
                           if per.get(name) else "no link of it cut")
            for name in lost) if lost else ""
        flags.append({"flag": "images-lost",
                      "message": f"cleaning lost {reg_b - reg_a} registered image(s) "
                                 f"({reg_b} -> {reg_a}){': ' + ', '.join(lost) if lost else ''}",
                      "likely_cause": (f"the links cut ({cut_text}) left those images with too "
                                       f"few matches to register"
                                       + (f" ({detail})" if detail else "")
                                       + "; the reconstruction before cleaning is better for "
                                         "them (run with --no-fusion to keep fusion's cuts "
                                         "out)")})
    worse = []
    p_b, p_a = int(before["points"]), int(after["points"])
    # a model without a point has no mean (None): it compares as 0, as its points do
    e_b, e_a = (float(s["mean_reprojection_error"] or 0.0) for s in (before, after))
    t_b, t_a = (float(s["mean_track_length"] or 0.0) for s in (before, after))
    # fewer points with a smaller error and tracks as long: the points that went were the
    # inconsistent ones, which is what cleaning is for (a few points of a small model)
    sharper = 0 < e_a < e_b and t_a >= (1 - TOLERANCE) * t_b
    if p_b and p_a < (1 - TOLERANCE) * p_b and not sharper:
        worse.append(f"points {p_b} -> {p_a}")
    if p_a and t_a < (1 - TOLERANCE) * t_b:
        worse.append(f"mean track length {t_b:.2f} -> {t_a:.2f}")
    if e_b and e_a > (1 + TOLERANCE) * e_b:
        worse.append(f"mean reprojection error {e_b:.3f} -> {e_a:.3f} px")
    if worse and reg_b:
        flags.append({"flag": "cleaning-worse",
                      "message": "cleaning made the reconstruction worse: " + "; ".join(worse),
                      "likely_cause": f"links cut: {cut_text}; cutting links shortens tracks "
                                      f"and removes points whose only support was cut"})
    return flags


def _few(names: list[str], shown: int = 5) -> str:
    more = len(names) - shown
    return ", ".join(names[:shown]) + (f" and {more} more" if more > 0 else "")


def _other_models(summary: dict) -> str:
    """What COLMAP's other models held (``summary["other_models"]``), or ''."""
    others = summary.get("other_models") or []
    if not others:
        return ""
    held = sorted(name for names in others for name in names)
    return (f"; COLMAP made {len(others) + 1} models and sparse/ holds the largest only: the "
            f"other {'model' if len(others) == 1 else 'models'} registered {len(held)} "
            f"image(s) ({_few(held)})")


def flags_markdown(flags: list[dict]) -> str:
    """The flags as a markdown list for the report ('' when there are none)."""
    if not flags:
        return ""
    lines = ["", "**Warnings**", ""]
    lines += [f"- **{f['flag']}**: {f['message']}. Likely cause: {f['likely_cause']}."
              for f in flags]
    return "\n".join(lines) + "\n"
