"""Rerun recording of one run: what matching produced, what the consistency stage cut, and why.

Reads a :class:`pipeline.types.RunRecord` and writes a headless ``.rrd`` file; it never computes
results and never spawns a viewer (``make view`` opens the file). The layout follows Rerun's
structure-from-motion example:

``world``                          axis convention, static
``world/NAME``                     ``Transform3D`` from ``cam_from_world`` (``x_cam = R x_world + t``);
                                   ``NAME`` is the image (file) name, escaped for Rerun
``world/NAME/image``               ``Pinhole`` + JPEG image
``world/NAME/image/keypoints``     ``Points2D``, class = keypoint status (see :data:`KEYPOINT_CLASSES`)
``world/links/kept``               ``LineStrips3D``, one green strip per kept link
``world/links/deleted``            ``LineStrips3D``, one strip per deleted link, coloured by the
                                   stage that cut it (:data:`CUT_COLORS`: resolution red, fusion
                                   purple)
``matches/A--B``                   the images ``A`` and ``B`` side by side with their links as
                                   2D strips: every cut link (``cut``) and an even sample of at
                                   most :data:`PAIR_KEPT_SAMPLE` kept ones (``kept``), one pair per
                                   ``view_pairs`` entry
``world/links/replay``             the same links, coloured per step of the ``round`` timeline
``world/points/{triangulated,ground_truth,fused}``  ``Points3D``
``graph``                          ``GraphNodes``/``GraphEdges``: conflictive sets before resolution
                                   (Aragüés et al., Def. 2.4), cuts replayed on ``round``
``resolution/log``                 ``TextLog``: what each step of the replay cut
``cuts``                           ``TextDocument``: how many links each stage cut, and why
``report``                         ``TextDocument`` (markdown)

The default blueprint answers "what was cut, where, and why" first: its first 3D view shows
the cut links (kept ones hidden: one click on ``world/links/kept`` shows them), beside it the
``cuts`` summary and the conflictive sets; the other tabs hold every link, the replay, the
pair view, the report.

Cameras without a pose (real images, ``R`` or ``t`` is ``None``; e.g. not registered by the
mapper) are logged under ``images/NAME`` instead of ``world/``, with their image and keypoints
but no frustum, and ``world/links/*`` leave out every link that touches one of them: a strip
needs both of its cameras. The conflict graph, the text panels and the ``round`` timeline of
the graph need no pose and are always logged.

The replay (Aragüés et al., Sec. IV, Alg. 1) runs on the ``round`` timeline. Its value is a
*step*, not the paper's round number, because rounds restart at every detection/resolution
iteration: step 0 shows every link as a candidate; step ``k`` is the ``k``-th distinct
``(stage, iteration, round)`` in which links were cut, in the order the run cut them
(:func:`replay_steps`: checks before the consistency stage, then the consistency stage by
``(iteration, round)`` with the links of robots declared lost among the resolution's cuts,
then the fusion); the last step shows the kept links as kept.
``resolution/log`` names the iteration and round of every step, where the ledger knows them.
"""

from __future__ import annotations

import colorsys
import contextlib
import errno
import os
import uuid
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from pipeline.types import RunRecord
from pipeline.validate import is_utf8_name

__all__ = [
    "CUT_COLORS",
    "CUT_WHY",
    "PAIR_KEPT_SAMPLE",
    "case_why",
    "check_recording_whole",
    "record_to_memory",
    "write_recording",
    "cut_summary",
    "KEYPOINT_CLASSES",
    "LINK_COLORS",
    "camera_entity",
    "default_view_pairs",
    "keypoint_annotation_context",
    "keypoint_status",
    "link_endpoints_3d",
    "log_run",
    "replay_steps",
    "STAGE_ORDER",
    "world_axes_from_cameras",
]

#: Keypoint status classes, ``class_id -> (label, RGB)``; the annotation context at ``/`` maps
#: the ``class_ids`` of every keypoint entity to these.
KEYPOINT_CLASSES = {
    0: ("other", (150, 150, 150)),
    1: ("kept in a track", (40, 200, 60)),
    2: ("conflictive before resolution", (255, 170, 0)),
    3: ("cut by resolution (endpoint of a deleted link)", (230, 40, 40)),
    4: ("cut by fusion or another stage (endpoint of a deleted link)", (160, 60, 255)),
}
#: Link colours (RGB): a candidate during the replay, kept, cut (by resolution).
LINK_COLORS = {"candidate": (190, 190, 190), "kept": (40, 200, 60), "cut": (230, 40, 40)}
#: Colour of a deleted link by the stage that cut it (``reason``); other reasons: ``other``.
CUT_COLORS = {"resolution": (230, 40, 40), "fusion-outlier": (160, 60, 255),
              "robot-lost": (255, 200, 0), "other": (255, 110, 180)}


#: Why a stage cuts a link (``reason`` of the ledger), for the ``cuts`` panel.
CUT_WHY = {
    "resolution": "it lay in a conflictive set (a chain of matches joining two features of one "
                  "camera, Def. 2.4: the graph view) and the resolution rule cut the set until "
                  "each camera appears once in it",
    "fusion-outlier": "the robust fusion of its landmark (distributed RANSAC, dynamic voting) "
                      "declared one of its two observations an outlier and not the other (the "
                      "outlier leaves the landmark; a link between two outliers is kept where they "
                      "can be one point)",
    "robot-lost": "one of its robots fell silent and its neighbours declared it lost",
    "not-one-to-one": "the input matched one keypoint to several of the other image",
    "not-comm-edge": "its two images are not neighbours in the communication graph",
    "loop-inconsistent": "its image pair's relative rotation breaks the rotation loops of the "
                         "view graph (clean-db --loop-check)",
}
#: How a resolution cut was decided (``case`` of the ledger).
CASE_WHY = {"evidence": "evidence rule: the least-supported links of the set",
            "sync": "multi-way matching: the link would have joined two features of one "
                    "camera in one landmark",
            "b": "Alg. 1, case (b)", "c": "Alg. 1, case (c)", "reject": "Alg. 1, a reject",
            "robot-lost": "its robot was lost"}
_COLOUR_NAMES = {(230, 40, 40): "red", (160, 60, 255): "purple", (255, 200, 0): "yellow"}
#: Kept links drawn in a pair view: an even sample of them, so that the cut ones stay readable.
PAIR_KEPT_SAMPLE = 25


def case_why(case: str) -> str:
    """How a resolution cut of ``case`` was decided: :data:`CASE_WHY`, else the title of the
    registered rule that writes that case (:mod:`pipeline.consistency.rules`: a rule added
    later), else the case itself."""
    if case in CASE_WHY:
        return CASE_WHY[case]
    from pipeline.consistency.rules import RULES

    rule = next((r for r in RULES.values() if case in r.cases.values()), None)
    return case if rule is None else f"{rule.name} rule: {rule.title}"


def cut_color(reason: str) -> tuple[int, int, int]:
    """RGB of a link cut for ``reason`` (:data:`CUT_COLORS`)."""
    return CUT_COLORS.get(str(reason), CUT_COLORS["other"])
# Kept links outnumber cut ones by 10-100x: draw them thin and translucent so the cut ones show.
_KEPT_ALPHA = 70
_KEPT_RADIUS = rr.components.Radius.ui_points(0.5)
_LINE_RADIUS = rr.components.Radius.ui_points(1.0)
_POINT_RADIUS = rr.components.Radius.ui_points(1.5)
_POINT_COLORS = {"triangulated": (255, 255, 255), "ground_truth": (60, 140, 255),
                 "fused": (230, 60, 230)}
_CUT_MARKER = "×"
#: Added to OpenCV pixel coordinates to get Rerun's: Rerun's pixel grid puts the top-left
#: pixel's centre at (0.5, 0.5), OpenCV's at (0, 0).
RERUN_PIXEL_OFFSET = 0.5


def camera_entity(i: int, posed: bool = True, name: str | None = None) -> str:
    """Entity path of camera ``i``: ``world/NAME`` if it has a pose, else ``images/NAME``.

    ``NAME`` is the image name escaped for Rerun (``rr.escape_entity_path_part``), or
    ``cam_XX`` without a name.
    """
    part = rr.escape_entity_path_part(str(name)) if name else f"cam_{i:02d}"
    return f"{'world' if posed else 'images'}/{part}"


def _camera_names(record: RunRecord) -> list[str | None]:
    """Names for the camera entities: the image names when they are unique and non-empty."""
    names = [str(v.name) if getattr(v, "name", "") else None for v in record.views]
    if None in names or len(set(names)) != len(names):
        return [None] * len(names)
    return names


def _offsets(record: RunRecord) -> np.ndarray:
    counts = [len(f) for f in record.features]
    return np.concatenate([[0], np.cumsum(counts, dtype=np.int64)]).astype(np.int64)


def _check_record(record: RunRecord) -> None:
    n = len(record.views)
    if len(record.features) != n:
        raise ValueError(f"RunRecord: {n} views but {len(record.features)} feature sets")
    record.ledger.check()


def keypoint_status(record: RunRecord) -> np.ndarray:
    """Status class of every feature, in global order ``offset[i] + r``.

    Parameters
    ----------
    record : RunRecord

    Returns
    -------
    ndarray, (m_sum,) uint8
        Class ids of :data:`KEYPOINT_CLASSES`. Precedence, highest first: *cut by resolution*,
        *cut by another stage* (endpoint of a deleted link), *conflictive* (endpoint of a link
        in a conflictive set before resolution, none of whose links was cut), *kept in a track*
        (endpoint of a kept link), *other*.

    Notes
    -----
    Every feature of a conflictive set ends either in a track or with all its links cut, so a
    single "after" status would never show *conflictive*; the precedence above keeps the
    three groups a reader wants to tell apart distinct.
    """
    off = _offsets(record)
    lk = record.ledger.links
    a = off[lk.cam_i] + lk.feat_i
    b = off[lk.cam_j] + lk.feat_j
    deleted = np.asarray(record.ledger.status) == "deleted"
    by_resolution = deleted & (np.asarray(record.ledger.reason, dtype=str) == "resolution")
    conflictive = np.asarray(record.ledger.conflictive_before, dtype=bool)
    status = np.zeros(int(off[-1]), dtype=np.uint8)
    # Later assignments win: write the classes in increasing precedence.
    for cls, mask in ((1, ~deleted), (2, conflictive), (4, deleted & ~by_resolution),
                      (3, by_resolution)):
        status[a[mask]] = cls
        status[b[mask]] = cls
    return status


def keypoint_annotation_context() -> rr.AnnotationContext:
    """The annotation context of :data:`KEYPOINT_CLASSES` (class id -> label, colour).

    Built as its Arrow array directly: equal to
    ``rr.AnnotationContext([(k, label, rgb), ...])``, whose conversion casts through
    ``pyarrow.compute`` and so imports it (a tenth of a second) for five classes.
    """
    import pyarrow as pa

    rows = [{"class_id": k,
             "class_description": {"info": {"id": k, "label": label,
                                            "color": (r << 24) | (g << 16) | (b << 8) | 0xFF},
                                   "keypoint_annotations": [], "keypoint_connections": []}}
            for k, (label, (r, g, b)) in KEYPOINT_CLASSES.items()]
    return rr.AnnotationContext(pa.array(
        [rows], type=rr.components.AnnotationContextBatch._ARROW_DATATYPE))


def _has_pose(view) -> bool:
    return view.R is not None and view.t is not None


def _pinhole_K(K: np.ndarray) -> np.ndarray:
    """``K`` in Rerun's pixel convention (:data:`RERUN_PIXEL_OFFSET`)."""
    K = np.array(K, dtype=np.float64, copy=True)
    K[:2, 2] += RERUN_PIXEL_OFFSET
    return K


def _default_plane_distance(views) -> float:
    """0.4 x the median nearest-neighbour distance between camera centres (1 if unknown).

    Large enough to see the images on the frusta, small enough that neighbours' do not overlap.
    """
    centres = np.stack([-np.asarray(v.R).T @ np.asarray(v.t) for v in views if _has_pose(v)])
    if len(centres) < 2:
        return 1.0
    d = np.linalg.norm(centres[:, None] - centres[None], axis=-1)
    np.fill_diagonal(d, np.inf)
    nn = np.median(d.min(axis=1))
    return float(0.4 * nn) if np.isfinite(nn) and nn > 0 else 1.0


def link_endpoints_3d(record: RunRecord, depth: float) -> np.ndarray:
    """Both keypoints of every link back-projected to depth ``depth`` in their cameras.

    Parameters
    ----------
    record : RunRecord
    depth : float
        z-depth in the camera frame (the pinhole image-plane distance, so a strip ends on the
        keypoint drawn on the image plane).

    Returns
    -------
    ndarray, (L, 2, 3) float32
        World coordinates, ``X = R^T (depth K^-1 [u, v, 1]^T - t)`` for each endpoint; ``NaN`` for
        an endpoint whose camera has no pose.
    """
    views = record.views
    posed = np.array([_has_pose(v) for v in views], dtype=bool)
    kp = np.concatenate([np.asarray(f.keypoints, dtype=np.float64).reshape(-1, 2)
                         for f in record.features] + [np.zeros((0, 2))])
    off = _offsets(record)
    K_inv = np.stack([np.linalg.inv(np.asarray(v.K, dtype=np.float64)) for v in views])
    R = np.stack([np.asarray(v.R, dtype=np.float64) if p else np.full((3, 3), np.nan)
                  for v, p in zip(views, posed, strict=True)])
    t = np.stack([np.asarray(v.t, dtype=np.float64).reshape(3) if p else np.full(3, np.nan)
                  for v, p in zip(views, posed, strict=True)])
    lk = record.ledger.links
    ends = []
    for cam, feat in ((lk.cam_i, lk.feat_i), (lk.cam_j, lk.feat_j)):
        uv1 = np.concatenate([kp[off[cam] + feat], np.ones((len(cam), 1))], axis=1)
        ray = np.einsum("nij,nj->ni", K_inv[cam], uv1)
        x_cam = depth * ray / ray[:, 2:3]
        ends.append(np.einsum("nji,nj->ni", R[cam], x_cam - t[cam]))  # R^T (x_cam - t)
    return np.stack(ends, axis=1).astype(np.float32)


#: When each ``reason`` cuts its links in a run: ``(phase, rank)``. Phase 0 are the checks
#: before the consistency stage (``clean-db``, ``clean-h5``), phase 1 the consistency stage
#: (the resolution and the robots declared lost, whose cuts share one ``(iteration, round)``
#: clock), phase 2 the fusion after it; any other reason comes last.
STAGE_ORDER = {"not-one-to-one": (0, 0), "not-comm-edge": (0, 1), "loop-inconsistent": (0, 2),
               "resolution": (1, 0), "robot-lost": (1, 1), "fusion-outlier": (2, 0)}


def _replay_order(key: tuple[str, int, int]) -> tuple:
    stage, iteration, rnd = key
    phase, rank = STAGE_ORDER.get(stage, (3, 0))
    if phase == 1:  # one stage: its cuts in the order they were made
        return (phase, iteration, rnd, rank, stage)
    return (phase, rank, stage, iteration, rnd)


def replay_steps(record: RunRecord) -> tuple[np.ndarray, list[tuple[str, int, int]]]:
    """Step of the ``round`` timeline at which each link is cut.

    Returns
    -------
    step : ndarray, (L,) int64
        ``1..S`` for deleted links, ``S + 1`` for kept links (shown as kept at the last step).
    keys : list of (stage, iteration, round), length S
        What step ``k`` replays (``keys[k - 1]``), in the order the run cut the links
        (:data:`STAGE_ORDER`): the checks before the consistency stage, then the consistency
        stage by ``(iteration, round)`` (a robot declared lost cuts its links in the round
        it was declared, among the resolution's cuts), then the fusion, then any other
        stage in name order; within a stage by ``(iteration, round)``.
    """
    deleted = np.flatnonzero(np.asarray(record.ledger.status) == "deleted")
    reason = np.asarray(record.ledger.reason, dtype=str).reshape(-1)
    it = np.asarray(record.ledger.iteration, dtype=np.int64).reshape(-1)
    rd = np.asarray(record.ledger.round, dtype=np.int64).reshape(-1)
    names, stage_of = np.unique(reason[deleted], return_inverse=True)
    triples = np.stack([stage_of.reshape(-1), it[deleted], rd[deleted]], axis=1).reshape(-1, 3)
    uniq, inv = np.unique(triples, axis=0, return_inverse=True)
    keys = [(str(names[s]), int(i), int(r)) for s, i, r in uniq]
    order = sorted(range(len(keys)), key=lambda k: _replay_order(keys[k]))
    rank = np.empty(len(keys), dtype=np.int64)
    rank[order] = np.arange(len(keys))
    step = np.full(len(record.ledger.links), len(keys) + 1, dtype=np.int64)
    step[deleted] = rank[inv.reshape(-1)] + 1
    return step, [keys[k] for k in order]


def _node_ids(cam: np.ndarray, feat: np.ndarray) -> np.ndarray:
    return np.char.add(np.char.add(cam.astype(str), ":"), feat.astype(str))


def _camera_palette(n: int) -> np.ndarray:
    """``n`` well-separated RGB colours (golden-ratio hue steps), (n, 3) uint8."""
    hues = (np.arange(n) * 0.618033988749895) % 1.0
    return (np.array([colorsys.hsv_to_rgb(h, 0.75, 0.95) for h in hues]).reshape(-1, 3)
            * 255).astype(np.uint8)


def _log_graph(rec: rr.RecordingStream, record: RunRecord, step: np.ndarray) -> None:
    """Conflictive sets before resolution as one graph, replayed on the ``round`` timeline.

    Nodes are the features of the conflictive sets (Aragüés et al., Def. 2.4), labelled
    ``camera:feature`` and coloured by camera, so a conflict shows as two nodes of one colour
    in one component. Edges are the links of those sets. ``GraphEdges`` carries no colour in
    Rerun 0.41, so each link the run deleted is drawn as two edges through a ``×`` node; the
    ``×`` is grey (candidate) until the step that cuts the link and red from then on. Links
    without ``×`` are kept. Node ids, labels and edges are static; only the colours are logged
    per step, so the replay costs 4 bytes per node and step.
    """
    conf = np.flatnonzero(np.asarray(record.ledger.conflictive_before, dtype=bool))
    if conf.size == 0:
        return
    lk = record.ledger.links
    a = _node_ids(lk.cam_i[conf], lk.feat_i[conf])
    b = _node_ids(lk.cam_j[conf], lk.feat_j[conf])
    feat_ids, first = np.unique(np.concatenate([a, b]), return_index=True)
    feat_cams = np.concatenate([lk.cam_i[conf], lk.cam_j[conf]])[first]
    feat_colors = _camera_palette(len(record.views))[feat_cams]
    cut = np.asarray(record.ledger.status)[conf] == "deleted"
    markers = np.char.add("cut:", conf[cut].astype(str))
    edges = np.concatenate([np.stack([a[~cut], b[~cut]], axis=1),
                            np.stack([a[cut], markers], axis=1),
                            np.stack([markers, b[cut]], axis=1)])
    rec.log("graph",
            rr.GraphNodes(np.concatenate([feat_ids, markers]),
                          labels=np.concatenate([feat_ids, np.full(len(markers), _CUT_MARKER)]),
                          show_labels=True),
            rr.GraphEdges(edges.tolist(), graph_type="undirected"),
            static=True)
    marker_step = step[conf[cut]]
    for s in [0, *np.unique(marker_step).tolist()]:
        marker_colors = np.where((marker_step <= s)[:, None], LINK_COLORS["cut"],
                                 LINK_COLORS["candidate"])
        rec.set_time("round", sequence=int(s))
        rec.log("graph", rr.GraphNodes.from_fields(
            colors=np.concatenate([feat_colors, marker_colors]).astype(np.uint8)))


def _log_links(rec: rr.RecordingStream, record: RunRecord, step: np.ndarray,
               keys: list, depth: float) -> None:
    """Kept, deleted and replayed links as 3D strips, for links whose two cameras have a pose."""
    ends = link_endpoints_3d(record, depth)
    drawable = np.isfinite(ends).all(axis=(1, 2))
    ends, step = ends[drawable], step[drawable]
    deleted = (np.asarray(record.ledger.status) == "deleted")[drawable]
    reason = np.asarray(record.ledger.reason, dtype=str)[drawable]
    lk = record.ledger.links.subset(drawable)
    labels = np.char.add(np.char.add(_node_ids(lk.cam_i, lk.feat_i), "–"),
                         _node_ids(lk.cam_j, lk.feat_j))
    truth = (np.full(len(record.ledger), -1, dtype=np.int64) if record.ledger.truth is None
             else record.ledger.truth.astype(np.int64))[drawable]
    labels = np.char.add(labels, np.array(["", " (spurious)", " (good)"])[np.clip(truth + 1, 0, 2)])
    rec.log("world/links/kept",
            rr.LineStrips3D(ends[~deleted], colors=(*LINK_COLORS["kept"], _KEPT_ALPHA),
                            radii=_KEPT_RADIUS,
                            labels=labels[~deleted], show_labels=False), static=True)
    case = np.asarray(record.ledger.case, dtype=str)[drawable]
    how = np.array([f" ({case_why(c)})" if c else "" for c in case[deleted]], dtype=str)
    del_labels = np.char.add(np.char.add(np.char.add(labels[deleted], " cut by "),
                                         reason[deleted]), how)
    cut_rgb = np.array([cut_color(r) for r in reason], dtype=np.uint8).reshape(-1, 3)
    rec.log("world/links/deleted",
            rr.LineStrips3D(ends[deleted], colors=cut_rgb[deleted], radii=_LINE_RADIUS,
                            labels=del_labels, show_labels=False), static=True)
    # Replay: geometry once (static), colours per step (temporal).
    rec.log("world/links/replay",
            rr.LineStrips3D(ends, radii=_KEPT_RADIUS), static=True)
    candidate = np.array((*LINK_COLORS["candidate"], _KEPT_ALPHA), dtype=np.uint8)
    kept = np.array((*LINK_COLORS["kept"], _KEPT_ALPHA), dtype=np.uint8)
    cut = np.concatenate([cut_rgb, np.full((len(cut_rgb), 1), 255, np.uint8)], axis=1)
    for s in range(len(keys) + 2):
        shown = (step <= s)[:, None]
        colors = np.where(shown, np.where(deleted[:, None], cut, kept), candidate)
        rec.set_time("round", sequence=s)
        rec.log("world/links/replay", rr.LineStrips3D.from_fields(colors=colors.astype(np.uint8)))


def default_view_pairs(record: RunRecord, count: int = 1) -> list[tuple[int, int]]:
    """Camera pairs worth a 2D matches view: most cut links first, then most links."""
    lk = record.ledger.links
    if len(lk) == 0:
        return []
    n = len(record.views)
    key = lk.cam_i * n + lk.cam_j
    deleted = np.asarray(record.ledger.status) == "deleted"
    pairs, total = np.unique(key, return_counts=True)
    cut = np.array([int(deleted[key == k].sum()) for k in pairs])
    order = np.lexsort((pairs, -total, -cut))[:count]
    return [(int(pairs[k] // n), int(pairs[k] % n)) for k in order]


def _gray_to_rgb(image: np.ndarray) -> np.ndarray:
    return np.repeat(image[..., None], 3, axis=2) if image.ndim == 2 else image[..., :3]


def jpeg_bytes(image: np.ndarray, quality: int) -> bytes | None:
    """JPEG bytes of an 8-bit gray ``(H, W)`` or RGB ``(H, W, 3)`` image, encoded by OpenCV;
    ``None`` for any other image."""
    import cv2

    image = np.asarray(image)
    if image.dtype != np.uint8 or not (image.ndim == 2
                                       or (image.ndim == 3 and image.shape[2] == 3)):
        return None
    bgr = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
    ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    return buf.tobytes() if ok else None


def _jpeg(image: np.ndarray, quality: int):
    """``image`` as a JPEG for the recording: :func:`jpeg_bytes` (OpenCV, already loaded by
    the run, which spares loading Pillow, the encoder of ``rr.Image.compress``) for 8-bit gray
    and RGB images; any other image goes through ``rr.Image.compress`` as before."""
    data = jpeg_bytes(image, quality)
    if data is not None:
        return rr.EncodedImage(contents=data, media_type="image/jpeg")
    return rr.Image(np.ascontiguousarray(image)).compress(jpeg_quality=quality)


def _log_pair(rec: rr.RecordingStream, record: RunRecord, i: int, j: int,
              names: list, jpeg_quality: int) -> str:
    """Images ``i`` and ``j`` side by side with their links as 2D strips, kept vs cut."""
    import cv2

    a, b = _gray_to_rgb(record.views[i].image), _gray_to_rgb(record.views[j].image)
    h = _pair_height(a.shape[:2], b.shape[:2])
    sa, sb = h / a.shape[0], h / b.shape[0]
    a = cv2.resize(a, (max(1, round(a.shape[1] * sa)), h)) if sa != 1 else a
    b = cv2.resize(b, (max(1, round(b.shape[1] * sb)), h)) if sb != 1 else b
    canvas = np.concatenate([a, b], axis=1)
    lk = record.ledger.links
    ni = names[i] or f"cam_{i:02d}"
    nj = names[j] or f"cam_{j:02d}"
    sel = np.flatnonzero(((lk.cam_i == i) & (lk.cam_j == j)) | ((lk.cam_i == j) & (lk.cam_j == i)))
    fi = np.where(lk.cam_i[sel] == i, lk.feat_i[sel], lk.feat_j[sel])
    fj = np.where(lk.cam_i[sel] == i, lk.feat_j[sel], lk.feat_i[sel])
    pa = (np.asarray(record.features[i].keypoints, np.float64)[fi] + 0.5) * sa
    pb = (np.asarray(record.features[j].keypoints, np.float64)[fj] + 0.5) * sb
    pb[:, 0] += a.shape[1]
    strips = np.stack([pa, pb], axis=1).astype(np.float32)
    deleted = np.asarray(record.ledger.status)[sel] == "deleted"
    reason = np.asarray(record.ledger.reason, dtype=str)[sel]
    entity = "matches/" + rr.escape_entity_path_part(f"{ni}--{nj}")
    rec.log(entity, _jpeg(canvas, jpeg_quality), static=True)
    kept = np.flatnonzero(~deleted)
    kept = kept[_even_sample(kept.size, PAIR_KEPT_SAMPLE)]
    rec.log(f"{entity}/kept", rr.LineStrips2D(strips[kept],
                                              colors=(*LINK_COLORS["kept"], 110),
                                              radii=rr.components.Radius.ui_points(0.75)),
            static=True)
    rec.log(f"{entity}/cut", rr.LineStrips2D(
        strips[deleted], colors=np.array([cut_color(r) for r in reason[deleted]],
                                         dtype=np.uint8).reshape(-1, 3),
        labels=np.char.add("cut by ", reason[deleted]), show_labels=False,
        radii=rr.components.Radius.ui_points(1.25)), static=True)
    return entity


def _pair_height(shape_a: tuple[int, int], shape_b: tuple[int, int]) -> int:
    """Height of the side-by-side pair canvas: the taller image's, lowered until the canvas is
    at most twice as wide as the wider image (a pair of one size is never scaled). A wide
    and a tall image (2000 x 60 beside 60 x 2000) would otherwise make a canvas 33 times
    wider than either, beyond what JPEG encodes (65500 px), and store it raw."""
    (ha, wa), (hb, wb) = shape_a, shape_b
    h = max(ha, hb)
    width = wa * h / ha + wb * h / hb
    limit = 2 * max(wa, wb)
    return max(1, int(h * limit / width)) if width > limit else h


def _even_sample(n: int, k: int) -> np.ndarray:
    """Indices of ``min(n, k)`` of ``range(n)``, evenly spread, in order."""
    return np.unique(np.linspace(0, n - 1, min(n, k)).round().astype(np.int64)) if n else \
        np.zeros(0, dtype=np.int64)


def _pair_counts(record: RunRecord, i: int, j: int) -> tuple[int, int]:
    """``(cut, kept)`` links between cameras ``i`` and ``j``."""
    lk = record.ledger.links
    sel = ((lk.cam_i == i) & (lk.cam_j == j)) | ((lk.cam_i == j) & (lk.cam_j == i))
    cut = int((sel & (np.asarray(record.ledger.status) == "deleted")).sum())
    return cut, int(sel.sum()) - cut


def cut_summary(record: RunRecord) -> str:
    """Markdown of the ``cuts`` panel: the links each stage cut, the colour they are drawn
    in, and why that stage cuts a link (:data:`CUT_WHY`, :func:`case_why`); read from the
    ledger only."""
    status = np.asarray(record.ledger.status)
    reason = np.asarray(record.ledger.reason, dtype=str)
    case = np.asarray(record.ledger.case, dtype=str)
    deleted = status == "deleted"
    n_conf = int(np.asarray(record.ledger.conflictive_before, dtype=bool).sum())
    lines = ["## What was cut, where, and why", "",
             f"**{int(deleted.sum())} of {len(status)} links cut**, "
             f"{int((~deleted).sum())} kept; {n_conf} links lay in conflictive sets before "
             "the resolution.", ""]
    names, counts = np.unique(reason[deleted], return_counts=True)
    order = sorted(range(len(names)), key=lambda k: (names[k] != "resolution", names[k]))
    for k in order:
        name = str(names[k])
        why = CUT_WHY.get(name, "cut by that stage")
        cases, c_counts = np.unique(case[deleted & (reason == name)], return_counts=True)
        how = [f"{case_why(str(c))}: {int(n)}"
               for c, n in zip(cases, c_counts, strict=True) if c]
        if name == "resolution" and how:
            why += " (" + "; ".join(how) + ")"
        lines.append(f"* **{_links(int(counts[k]))} cut by {name}** (drawn "
                     f"{_COLOUR_NAMES.get(cut_color(name), 'pink')}): {why}.")
    posed = np.array([_has_pose(v) for v in record.views], dtype=bool)
    lk = record.ledger.links
    unposed = ~(posed[lk.cam_i] & posed[lk.cam_j]) if len(posed) else np.zeros(0, bool)
    if not posed.any():  # no 3D view of the links (the blueprint's side panel only)
        where = ("No image has a pose, so no link is drawn in 3D: the graph and the pair "
                 "view show them. ")
    else:
        where = ("The first 3D view shows the cut links between the cameras that made them; "
                 "the kept links (green) are hidden there: show them with the eye of "
                 "`world/links/kept`, or open the tab *All links*. A cut link's label (hover) "
                 "names its two features, its stage and, with ground truth, whether it was "
                 "good or spurious. ")
        if unposed.any():  # a strip needs both of its cameras' poses
            where += (f"{_links(int((unposed & deleted).sum()))} cut and "
                      f"{_links(int((unposed & ~deleted).sum()))} kept touch an image without "
                      "a pose (one the mapper did not register, under `images/`): counted "
                      "here, not drawn in 3D. ")
    lines += ["", where + (
                  "The graph shows each conflictive set as it was before the resolution, a "
                  "`×` on every link the run cut; " if n_conf else
                  "There was no conflictive set before the resolution, so the graph is "
                  "empty; ") +
              "the pair view draws every cut "
              f"link of one image pair and at most {PAIR_KEPT_SAMPLE} of its kept links."]
    return "\n".join(lines)


def _log_replay_text(rec: rr.RecordingStream, step: np.ndarray, keys: list, n_kept: int) -> None:
    rec.set_time("round", sequence=0)
    rec.log("resolution/log",
            rr.TextLog(f"step 0: {_links(len(step))} from matching, all candidates"))
    counts = np.bincount(step, minlength=len(keys) + 2)
    for k, (stage, iteration, rnd) in enumerate(keys, start=1):
        rec.set_time("round", sequence=k)
        when = "".join(f", {name} {v}" for name, v in (("iteration", iteration), ("round", rnd))
                       if v >= 0)  # -1: not known (a saved run) or not one of the stage's
        rec.log("resolution/log",
                rr.TextLog(f"step {k}: {stage}{when}: {_links(counts[k])} cut"))
    rec.set_time("round", sequence=len(keys) + 1)
    rec.log("resolution/log", rr.TextLog(f"step {len(keys) + 1}: {_links(n_kept)} kept"))


def _links(n: int) -> str:
    return f"{n} link" if n == 1 else f"{n} links"


_UP_AXES = {(0, 1): rr.ViewCoordinates.RIGHT_HAND_X_UP, (0, -1): rr.ViewCoordinates.RIGHT_HAND_X_DOWN,
            (1, 1): rr.ViewCoordinates.RIGHT_HAND_Y_UP, (1, -1): rr.ViewCoordinates.RIGHT_HAND_Y_DOWN,
            (2, 1): rr.ViewCoordinates.RIGHT_HAND_Z_UP, (2, -1): rr.ViewCoordinates.RIGHT_HAND_Z_DOWN}


def world_axes_from_cameras(views):
    """Right-handed world convention whose up axis is closest to the cameras' mean up direction.

    Synthetic formations (upright cameras, ``z`` up) give ``RIGHT_HAND_Z_UP``; a COLMAP model,
    whose frame follows its first cameras (``y`` down), gives ``RIGHT_HAND_Y_DOWN``. Without any
    pose: ``RIGHT_HAND_Z_UP``.
    """
    ups = [-np.asarray(v.R, dtype=np.float64)[1] for v in views if _has_pose(v)]
    if not ups:
        return rr.ViewCoordinates.RIGHT_HAND_Z_UP
    up = np.mean(ups, axis=0)  # camera y points down in the image (OpenCV / RDF)
    k = int(np.argmax(np.abs(up)))
    return _UP_AXES[(k, 1 if up[k] >= 0 else -1)]


def _default_eye(views) -> rrb.EyeControls3D | None:
    """Look over the formation from behind and above, towards where the cameras point."""
    posed = [v for v in views if _has_pose(v)]
    if not posed:
        return None
    centres = np.stack([-np.asarray(v.R).T @ np.asarray(v.t).reshape(3) for v in posed])
    forward = np.mean([np.asarray(v.R)[2] for v in posed], axis=0)
    down = np.mean([np.asarray(v.R)[1] for v in posed], axis=0)
    spread = max(float(np.ptp(centres, axis=0).max()), 1e-3)
    forward /= max(float(np.linalg.norm(forward)), 1e-9)
    down /= max(float(np.linalg.norm(down)), 1e-9)
    centre = centres.mean(axis=0)
    return rrb.EyeControls3D(position=centre - 1.0 * spread * forward - 0.7 * spread * down,
                             look_target=centre + 0.5 * spread * forward, eye_up=-down)


def _blueprint(record: RunRecord, posed: list[bool], max_image_views: int,
               pairs: list[tuple[str, int, int]] = ()) -> rrb.Blueprint:
    """The default layout: what was cut, where and why first (see the module docstring).

    ``pairs``: ``(entity, i, j)`` of every pair view."""
    names = _camera_names(record)
    image_views = [rrb.Spatial2DView(origin=f"{camera_entity(i, p, names[i])}/image", name=v.name)
                   for i, (v, p) in enumerate(zip(record.views, posed, strict=True))][:max_image_views]
    pair_views = []
    for entity, i, j in pairs:
        cut, kept = _pair_counts(record, i, j)
        pair_views.append(rrb.Spatial2DView(
            origin=entity, name=f"Matches {entity.split('/', 1)[1].replace(chr(92), '')}: "
                                f"{cut} cut, {min(kept, PAIR_KEPT_SAMPLE)} of {kept} kept"))
    side = [rrb.TextDocumentView(origin="cuts", name="What was cut, and why"),
            rrb.Tabs(rrb.GraphView(origin="graph", name="Conflictive sets (× = link cut)"),
                     *pair_views,
                     rrb.TextDocumentView(origin="report", name="Report"),
                     rrb.TextLogView(origin="resolution", name="Resolution steps"))]
    if image_views:
        side.append(rrb.Grid(*image_views))
    side_panel = rrb.Vertical(*side, row_shares=[2, 3, 2][:len(side)])
    eye = _default_eye(record.views)
    if any(posed):
        main = rrb.Tabs(
            rrb.Spatial3DView(origin="world",
                              name="Cut links (red: resolution, purple: fusion); kept hidden",
                              contents=["+ $origin/**", "- $origin/links/replay"],
                              overrides={path: rrb.EntityBehavior(visible=False) for path in (
                                  "/world/links/kept", "/world/points/ground_truth",
                                  "/world/points/fused")},
                              eye_controls=eye),
            rrb.Spatial3DView(origin="world", name="All links: kept (faint green) and cut",
                              contents=["+ $origin/**", "- $origin/links/replay"],
                              eye_controls=eye),
            rrb.Spatial3DView(origin="world", name="Resolution replay (round timeline)",
                              contents=["+ $origin/**", "- $origin/links/kept",
                                        "- $origin/links/deleted"], eye_controls=eye),
        )
        layout = rrb.Horizontal(main, side_panel, column_shares=[3, 2])
    elif record.points is not None and len(record.points):
        layout = rrb.Horizontal(rrb.Spatial3DView(origin="world", name="Triangulated points"),
                                side_panel, column_shares=[3, 2])
    else:
        layout = side_panel
    return rrb.Blueprint(layout, rrb.TimePanel(timeline="round", play_state="following"),
                         collapse_panels=False)



@contextlib.contextmanager
def recording_file(path: str | os.PathLike):
    """Yield ``(tmp, sink)``: the temporary file beside ``path`` that a recording is written to
    (then renamed to ``path``) and the path to give Rerun's file sink for it.

    Rerun takes a path as UTF-8 text: in a folder whose path is not (Latin-1 bytes) the sink
    reaches the file through an open descriptor of the folder, ``/proc/self/fd/N/``, and the
    temporary name spells such bytes as ``\\xNN``.
    """
    path = Path(path)
    name = path.name if is_utf8_name(path.name) else os.fsencode(path.name).decode(
        "ascii", "backslashreplace")
    tmp = path.with_name(f".{name}.{uuid.uuid4().hex[:8]}.tmp")
    if is_utf8_name(str(tmp)):
        yield tmp, str(tmp)
        return
    fd = os.open(tmp.parent, os.O_RDONLY | os.O_DIRECTORY)
    try:
        yield tmp, f"/proc/self/fd/{fd}/{tmp.name}"
    finally:
        os.close(fd)


def record_to_memory(rec: rr.RecordingStream, blueprint=None) -> rr.BinaryStream:
    """Send ``rec``'s log to a stream held in memory (read by :func:`write_recording`), with
    ``blueprint`` as its default (as ``rec.save(..., default_blueprint=...)`` gives it).

    A recording is written by this process, not by Rerun's file sink: that sink reports a
    failed write only in its log and can then block for ever in ``disconnect`` (seen under a
    64 KB and a 256 KB file-size limit, 2 of 9 runs never ended), so a full disk would hang
    the command after its whole run. The recording is held whole until written (a few MB:
    JPEG images, keypoints and links)."""
    stream = rec.binary_stream()
    if blueprint is not None:
        rec.send_blueprint(blueprint, make_active=False, make_default=True)
    return stream


def write_recording(rec: rr.RecordingStream, stream: rr.BinaryStream, tmp: Path,
                    path: str | os.PathLike) -> None:
    """End ``rec`` (its footer) and write everything ``stream`` holds to ``tmp``, flushed to
    the disk: a failed write (a full disk, a file-size limit, a quota) is an ``OSError``
    naming ``path``, the recording it was for."""
    rec.disconnect()  # writes the footer; the file does not read back without it
    data = stream.read(flush=True) or b""
    try:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
    except OSError as e:
        raise OSError(e.errno, f"the recording ({len(data) / 1e6:.1f} MB) could not be written: "
                      f"{e.strerror}; nothing was put in its place", str(path)) from None


def check_recording_whole(sink: str | os.PathLike, path: str | os.PathLike) -> None:
    """OSError naming ``path`` unless the recording file ``sink`` was written in full.

    Rerun's file sink reports a failed write (a full disk, a file-size limit, a quota) only in
    its log, and leaves the file cut where the write failed, without its footer: such a file
    reads back with a warning, which is an error here.
    """
    import warnings

    from rerun.chunk import RrdReader
    from rerun.error_utils import RerunWarning

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", RerunWarning)
            RrdReader(Path(sink))
    except (RerunWarning, RuntimeError, OSError, ValueError):
        raise OSError(errno.EIO, "the recording was not written in full (a full disk or a "
                      "file-size limit: Rerun's message above says why); nothing was put in "
                      "its place", str(path)) from None


def log_run(path: str | os.PathLike, record: RunRecord, application_id: str = "formation-match",
            recording_name: str | None = None, *, image_plane_distance: float | None = None,
            world_axes=None, jpeg_quality: int = 85,
            max_image_views: int = 4, view_pairs: list[tuple[int, int]] | None = None,
            live: str | None = None) -> Path:
    """Write the Rerun recording of one run to ``path`` (headless; no viewer is spawned).

    Parameters
    ----------
    path : str or PathLike
        Output ``.rrd`` file. Written to a temporary sibling first, then renamed, so a failure
        leaves no half-written recording.
    record : RunRecord
        What the run produced; only read.
    application_id : str
        Rerun application id (groups recordings in the viewer).
    recording_name : str, optional
        Name shown for the recording in the viewer.
    image_plane_distance : float, optional
        Depth of the drawn image planes, and of the link strip endpoints, in world units.
        Default: 0.4 x the median nearest-neighbour distance between camera centres.
    world_axes : rr.ViewCoordinates, optional
        Axis convention of the world frame, logged once as static on ``world``. Default:
        :func:`world_axes_from_cameras` (``RIGHT_HAND_Z_UP`` for the synthetic formations).
    jpeg_quality : int
        JPEG quality of the logged images (the 6 rendered 640x480 images of formation d take
        0.38 MB at 85; the whole recording of that run is 1.1 MB).
    max_image_views : int
        How many cameras get a 2D view in the default blueprint.
    view_pairs : list of (i, j), optional
        Camera pairs drawn side by side with their links, kept vs cut (``matches/A--B``).
        Default: :func:`default_view_pairs` (the pair with the most cut links).
    live : str, optional
        Also stream to a live viewer: ``"spawn"`` starts one, ``"connect"`` or a
        ``rerun+http://…`` URL connects to a running one. The file is written either way.

    Returns
    -------
    Path
        ``path``.

    Notes
    -----
    See the module docstring for the entity layout. When every camera has a pose,
    ``world/links/deleted`` holds exactly one strip per deleted link and ``world/links/kept`` one
    per kept link (:func:`viz.recording_reader.count_strips` reads them back); links touching a camera without a
    pose are left out of both, and both are absent when no camera has a pose.

    Examples
    --------
    >>> path = log_run(run_dir / "recording.rrd", record)  # doctest: +SKIP
    >>> from viz.recording_reader import count_strips  # doctest: +SKIP
    >>> deleted = (record.ledger.status == "deleted").sum()  # doctest: +SKIP
    >>> count_strips(path, "world/links/deleted") == deleted  # doctest: +SKIP
    True
    """
    _check_record(record)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)

    posed = [_has_pose(v) for v in record.views]
    depth = float(image_plane_distance) if image_plane_distance else (
        _default_plane_distance(record.views) if any(posed) else 1.0)
    step, keys = replay_steps(record)
    status = keypoint_status(record)
    off = _offsets(record)
    cam_colors = _camera_palette(len(record.views))  # frusta match the graph's node colours

    names = _camera_names(record)
    pairs = default_view_pairs(record) if view_pairs is None else list(view_pairs)
    pair_entities = [("matches/" + rr.escape_entity_path_part(
        f"{names[i] or f'cam_{i:02d}'}--{names[j] or f'cam_{j:02d}'}"), int(i), int(j))
        for i, j in pairs]
    blueprint = _blueprint(record, posed, max_image_views, pair_entities)
    files = contextlib.ExitStack()
    tmp, sink = files.enter_context(recording_file(path))
    rec = rr.RecordingStream(application_id, recording_id=uuid.uuid4())
    try:
        if live:
            url = None if live == "connect" else live
            if live == "spawn":  # bound to loopback, which rr.spawn cannot do
                from viz.view import spawn_viewer

                url = spawn_viewer()
            rec.set_sinks(rr.FileSink(sink), rr.GrpcSink(url), default_blueprint=blueprint)
            stream = None
        else:
            stream = record_to_memory(rec, blueprint)
        rec.set_log_time_enabled(False)
        if recording_name:
            rec.send_recording_name(recording_name)

        rec.log("/", keypoint_annotation_context(), static=True)
        rec.log("world", world_axes if world_axes is not None
                else world_axes_from_cameras(record.views), static=True)

        for i, (view, feats) in enumerate(zip(record.views, record.features, strict=True)):
            cam = camera_entity(i, posed[i], names[i])
            w, h = view.size
            if posed[i]:
                rec.log(cam, rr.Transform3D(mat3x3=np.asarray(view.R, dtype=np.float64),
                                            translation=np.asarray(view.t, dtype=np.float64).reshape(3),
                                            relation=rr.TransformRelation.ChildFromParent),
                        static=True)
            rec.log(f"{cam}/image",
                    rr.Pinhole(image_from_camera=_pinhole_K(view.K), resolution=[w, h],
                               camera_xyz=rr.ViewCoordinates.RDF,
                               image_plane_distance=depth, color=cam_colors[i]),
                    static=True)
            rec.log(f"{cam}/image", _jpeg(view.image, jpeg_quality), static=True)
            kp = np.asarray(feats.keypoints, dtype=np.float32).reshape(-1, 2) + RERUN_PIXEL_OFFSET
            rec.log(f"{cam}/image/keypoints",
                    rr.Points2D(kp, class_ids=status[off[i]:off[i + 1]],
                                radii=rr.components.Radius.ui_points(1.5)),
                    static=True)

        if any(posed):
            _log_links(rec, record, step, keys, depth)

        points = {"triangulated": record.points, "ground_truth": record.gt_points,
                  "fused": record.fused_points}
        for name, pts in points.items():
            if pts is None:
                continue
            pts = np.asarray(pts, dtype=np.float32).reshape(-1, 3)
            labels = None
            if name == "triangulated" and record.point_tracks is not None \
                    and len(record.point_tracks) == len(pts):
                labels = np.char.add("track ", np.asarray(record.point_tracks).astype(str))
            colors = _POINT_COLORS[name]
            own = getattr(record, "point_colors", None)
            if name == "triangulated" and own is not None and len(own) == len(pts):
                colors = np.asarray(own, dtype=np.uint8).reshape(-1, 3)  # from the images
            rec.log(f"world/points/{name}",
                    rr.Points3D(pts, colors=colors, radii=_POINT_RADIUS,
                                labels=labels, show_labels=False if labels is not None else None),
                    static=True)

        for i, j in pairs:
            _log_pair(rec, record, int(i), int(j), names, jpeg_quality)
        _log_graph(rec, record, step)
        _log_replay_text(rec, step, keys, int((np.asarray(record.ledger.status) == "kept").sum()))
        rec.log("cuts", rr.TextDocument(cut_summary(record), media_type=rr.MediaType.MARKDOWN),
                static=True)
        rec.log("report", rr.TextDocument(record.report_markdown or "_no report_",
                                          media_type=rr.MediaType.MARKDOWN), static=True)
        if stream is None:
            rec.disconnect()  # writes the footer; the file does not read back without it
        else:
            write_recording(rec, stream, tmp, path)
        check_recording_whole(sink, path)
        os.replace(tmp, path)
    except BaseException:
        rec.disconnect()
        if tmp.exists():
            tmp.unlink()
        raise
    finally:
        files.close()
    return path
