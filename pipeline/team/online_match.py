"""One robot's matching of an online step, in its own process (``run-formation --steps N``
and ``run-images DIR --sequence`` over Zenoh).

Robot ``i`` of a team of ``n`` robots takes frame ``t · n + i`` at step ``t`` (the frame ids of
:func:`pipeline.runs.online.associate_online`). It keeps, in its own folder (``data.store``,
read and written by it alone), the features of its frames of the last ``W`` steps
(``data.window``): its memory between steps, which follows its window. At step ``t``
(``data.step``), with the robots it talks to at that step (the team's comm graph):

1. it loads its new frame (``data.frames[i]``: the pixels its camera delivered, ``K``, whether
   ``K`` is known, the pose where the robot knows it), extracts its features with the run's
   options (as :func:`pipeline.matching.features.extract_all` does for the simulator), stores
   them and drops its frames that left the window;
2. it sends each neighbour ``j`` the features ``j`` matches with and does not hold yet: its
   frames of steps ``t - W + 1 .. t - 1`` (``j``'s new frame against them), and its new frame
   when ``i > j`` (two new frames are matched by the robot of the lower id); SIFT as bytes, as
   the batch robots send them (:mod:`pipeline.matching.packed`). A robot keeps the frames it
   receives in its folder while they are in the window, and records what it sent to whom
   (``sent.json``), pruned by the same rule: each frame crosses each link once;
3. after one round it matches the pairs of :func:`pipeline.matching.pairs.step_pairs` that are its
   own: its new frame against its own older window frames and against every frame it
   received, each pair ``(a, b)``, ``a < b``, by :func:`pipeline.matching.pairs.match_pair` as
   :func:`pipeline.matching.pairs.match_edges` matches it (same orientation, same options);
4. it publishes the new frame's keypoints and its pairs' matches (the launching process
   orders them as the simulator's matching and goes on with the step); a frame it matches
   that never came (its robot lost: stopped, killed or cut off during the step) it names
   under ``missing`` and matches the pairs it has both frames of; the launching process
   starts the step's matching again with ``data.resend`` (each robot then sends its window
   frames again, whatever its ``sent.json`` says: what it sent may not have been kept).

*Void frames* (``data.void``: global frame ids of the window). A robot lost by the team
started again too never published its new frame: the launching process keeps the step going
without it (:func:`pipeline.runs.transports.zenoh.online_match`), and that frame is *void*
from then on: it has no features, and no robot stores, sends or matches it at a later step
(its own robot drops it from its folder if it had stored it before it was lost: the features
it would hold are not the run's). Every robot reads the same list, so the pairs it matches
are :func:`own_pairs` without those that touch a void frame, and the launching process
expects exactly these.

Every pair of the step is matched by exactly one robot: a pair joins a new frame and a window
frame of two robots that talk (or of one robot); the new frame's robot matches it, and of two
new frames the lower robot's.
"""

from __future__ import annotations

import json
import os
import resource
import time
from pathlib import Path

import numpy as np

__all__ = ["online_match_main", "frame_file", "write_frame", "load_frame", "own_pairs"]


def frame_file(folder, g: int) -> Path:
    """A robot's stored features of frame ``g`` in its folder."""
    return Path(folder) / f"frame-{int(g)}.npz"


def write_frame(path, view) -> None:
    """What a robot's camera delivers for one frame, as ``load_frame`` reads it."""
    from pipeline.runfolder import atomic_file

    arrays = {"image": np.asarray(view.image), "K": np.asarray(view.K, np.float64),
              "intrinsics_known": np.array([bool(view.intrinsics_known)])}
    if view.R is not None and view.t is not None:
        arrays["R"] = np.asarray(view.R, np.float64)
        arrays["t"] = np.asarray(view.t, np.float64).reshape(3)
    with atomic_file(path, mode="wb") as f:
        np.savez(f, **arrays)


def load_frame(path, name: str):
    """The :class:`~pipeline.types.View` of a frame file written by :func:`write_frame`.

    Raises
    ------
    InputError
        Naming the file: not a NumPy ``.npz`` archive (or one holding pickled objects), an
        array missing, ``image`` not ``(H, W)`` or ``(H, W, 3)`` uint8 of at least 2 x 2
        pixels, ``K`` not a finite ``(3, 3)``, ``intrinsics_known`` not one boolean, ``R``
        and ``t`` (both or neither) not a finite ``(3, 3)`` and ``(3,)``.
    """
    from pipeline.errors import InputError
    from pipeline.inputs.npzfile import npz_arrays
    from pipeline.types import View

    where = f"frame file {str(path)!r}"
    try:
        arrays = npz_arrays(path)
    except ValueError as exc:
        raise InputError(f"{where} is not a frame of an online step ({exc}); the online stage "
                         "writes one per robot and step (.npz of image, K, "
                         "intrinsics_known)") from None
    for key in ("image", "K", "intrinsics_known"):
        if key not in arrays:
            raise InputError(f"{where} has no array {key!r}; a frame holds image, K, "
                             "intrinsics_known (and R, t where the pose is known)")
    image, K, known = arrays["image"], arrays["K"], arrays["intrinsics_known"]
    if image.dtype != np.uint8 or not (image.ndim == 2 or (image.ndim == 3 and
                                                          image.shape[2] == 3)) \
            or min(image.shape[:2]) < 2:
        raise InputError(f"{where}: image has shape {image.shape} and dtype {image.dtype}; "
                         "expected (H, W) or (H, W, 3) uint8 of at least 2 x 2 pixels")
    if ("R" in arrays) != ("t" in arrays):
        raise InputError(f"{where} holds {'R' if 'R' in arrays else 't'} without "
                         f"{'t' if 'R' in arrays else 'R'}; a known pose needs both")
    for key, shape in (("K", (3, 3)), ("R", (3, 3)), ("t", (3,))):
        a = arrays.get(key)
        if a is not None and (a.shape != shape or a.dtype.kind not in "fiu"
                              or not np.isfinite(a).all()):
            raise InputError(f"{where}: {key} {a.tolist() if a.size <= 12 else a.shape} is not "
                             f"a {shape} array of finite numbers")
    if known.dtype != np.bool_ or known.shape != (1,):
        raise InputError(f"{where}: intrinsics_known {known.tolist() if known.size <= 4 else known.shape} "
                         "is not one true/false value")
    posed = "R" in arrays
    return View(name=name, image=image, K=K.astype(np.float64),
                R=arrays["R"].astype(np.float64) if posed else None,
                t=arrays["t"].astype(np.float64) if posed else None,
                intrinsics_known=bool(known[0]))


def own_pairs(i: int, n: int, t: int, window: int, neighbours,
              void=()) -> list[tuple[int, int]]:
    """The pairs ``(a, b)``, ``a < b``, robot ``i`` matches at step ``t``: its new frame
    against its frames of the window's earlier steps and every window frame of the robots it
    talks to, except their new frames of a lower robot id (those match it), and except the
    pairs touching a ``void`` frame (module docstring)."""
    g = t * n + i
    out = [(t2 * n + i, g) for t2 in range(max(0, t - window + 1), t)]
    for j in sorted(int(k) for k in neighbours):
        out += [(t2 * n + j, g) for t2 in range(max(0, t - window + 1), t)]
        if j > i:
            out.append((g, t * n + j))
    void = {int(f) for f in void}
    return sorted(p for p in out if p[0] not in void and p[1] not in void)


def online_match_main(team, i: int, transport) -> tuple[dict, dict]:
    """Steps 1–4 of the module docstring for robot ``i``; returns (header, arrays) as
    :func:`pipeline.team.robot.robot_main` does (no link log: nothing is decided here)."""
    from pipeline.matching.packed import (
        extract_raw,
        matching_descriptors,
        pack_features,
        unpack_features,
    )
    from pipeline.matching.pairs import match_pair
    from pipeline.runfolder import atomic_file, write_json_atomic
    from pipeline.transport.wire import set_compression
    from pipeline.types import Features

    opts = team.options_for(i)
    set_compression(opts.get("wire", "compact") == "compact")
    data = team.data
    n, t, window = team.n, int(data["step"]), int(data["window"])
    store = team.resolve_path(data["store"][i])
    store.mkdir(parents=True, exist_ok=True)
    timings: dict = {}
    t0 = time.perf_counter()
    g = t * n + i
    view = load_frame(team.resolve_path(data["frames"][i]), f"frame-{g}")
    h, w = view.image.shape[:2]
    raw, rootsift = extract_raw(view, opts, opts["merge_radius"])
    own = {"keypoints": raw.keypoints, "raw": raw.descriptors, "scales": raw.scales,
           "K": np.asarray(view.K, np.float64), "known": np.array([view.intrinsics_known]),
           "size": np.array([w, h], np.int64)}

    def save(f: int, arrays: dict) -> None:
        with atomic_file(frame_file(store, f), mode="wb") as out:
            np.savez(out, **arrays)

    def stored(f: int) -> dict:
        with np.load(frame_file(store, f)) as z:
            return {k: z[k] for k in z.files}

    save(g, own)
    void = {int(f) for f in data.get("void", ())}
    for old in store.glob("frame-*.npz"):  # the robot's memory follows its window
        f = int(old.stem.split("-")[1])
        if f // n <= t - window or f in void:  # a void frame is none of the run's
            old.unlink()
    timings["features"] = time.perf_counter() - t0
    # what it sent each neighbour at earlier steps and the neighbour still keeps (the same
    # window rule on both sides): each frame crosses a link once
    sent_path = store / "sent.json"
    # started again after a robot was lost (data.resend): what it sent may not have been kept
    sent = json.loads(sent_path.read_text()) if sent_path.exists() and \
        not data.get("resend", False) else {}
    earlier = [s * n + i for s in range(max(0, t - window + 1), t) if s * n + i not in void]
    for j in sorted(transport.neighbours):
        had = {f for f in sent.get(str(j), []) if f // n > t - window}
        for f in earlier + ([g] if i > j else []):  # one message per frame
            if f in had:
                continue
            s = stored(f)
            transport.send(j, "frame", {**pack_features(s["keypoints"], s["raw"], rootsift),
                                        "id": np.array([f], np.int64), "K": s["K"],
                                        "known": s["known"], "size": s["size"]})
            had.add(f)
        sent[str(j)] = sorted(had)
    sent = {j: [f for f in fs if f // n > t - window] for j, fs in sent.items()}
    write_json_atomic(sent_path, {j: fs for j, fs in sent.items() if fs})
    t1 = time.perf_counter()
    inbox, _ = transport.end_round()
    for msg in inbox:  # kept while in the window: the sender sends a frame once
        if msg.kind == "frame":
            save(int(msg.payload["id"][0]), msg.payload)
    mine = own_pairs(i, n, t, window, transport.neighbours, void)
    missing = [f for f in sorted({f for pair in mine for f in pair})
               if not frame_file(store, f).exists()]
    # their robots were written off before sending them: the launcher decides; the pairs
    # of frames at hand are matched all the same (the launcher keeps them if it goes on)
    mine = [p for p in mine if p[0] not in missing and p[1] not in missing]
    feats, meta = {}, {}
    for pair in mine:
        for f in pair:
            if f in feats:
                continue
            s = stored(f)
            if "raw" in s:  # its own frame
                kp, desc, scales = s["keypoints"], matching_descriptors(s["raw"], rootsift), \
                    s["scales"]
            else:  # a neighbour's, as sent
                kp, desc = unpack_features(s)
                scales = np.zeros(len(kp), np.float32)
            feats[f] = Features(kp, desc, scales, raw.method)
            meta[f] = (s["K"].reshape(3, 3), bool(s["known"][0]),
                       tuple(int(v) for v in s["size"]))
    timings["exchange"] = time.perf_counter() - t1
    t2 = time.perf_counter()
    arrays = {"keypoints": raw.keypoints, "scales": raw.scales}
    header_pairs = []
    thr = opts.get("threshold_px", 1.0)  # None: scaled with the larger image
    for a, b in mine:
        (Ka, ka, sa), (Kb, kb, sb) = meta[a], meta[b]
        pm = match_pair(a, b, feats[a], feats[b], Ka, Kb, bool(ka and kb),
                        threshold_px=None if thr is None else float(thr),
                        matcher=opts.get("matcher", "opencv"), sizes=(sa, sb))
        header_pairs.append({"a": a, "b": b, "n_putative": int(pm.n_putative),
                             "reason": pm.reason})
        arrays[f"pairs_{a}_{b}"] = pm.pairs.astype(np.int32)
        arrays[f"ratio_{a}_{b}"] = pm.ratio.astype(np.float32)
        arrays[f"eperr_{a}_{b}"] = pm.epipolar_error.astype(np.float32)
    timings["matching"] = time.perf_counter() - t2
    timings["total"] = time.perf_counter() - t0
    held = 0  # bytes of the features it holds: its window's and those its neighbours sent
    for f in store.glob("frame-*.npz"):
        with np.load(f) as z:
            held += int(z["keypoints"].nbytes + z["raw" if "raw" in z.files else
                                                "descriptors"].nbytes)
    header = {"id": i, "frame": g, "pairs": header_pairs, "missing": missing,
              "held_bytes": held,
              "descriptor_bytes": int(raw.descriptors.nbytes),
              "counters": transport.counters(), "timings_s": timings,
              "peak_memory_bytes": held, "pid": os.getpid(),
              "peak_rss_bytes": 1024 * resource.getrusage(resource.RUSAGE_SELF).ru_maxrss}
    return header, arrays
