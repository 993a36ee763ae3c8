"""One robot of a team as its own program (``python -m pipeline robot --team TEAM.json --id I``).

The robot holds nothing global: no other robot's image, no union-find, no driver. In order:

1. **Its own data.** A rendered formation: it renders only its own camera
   (:func:`data_synth.render_robot`; the scene model is the world it looks at, the other
   cameras are not rendered). A photograph (``run-images``): it loads only its own file, with
   the intrinsics the team file gives it. A links file (``resolve``): its own file (``data.links``
   a list, one per robot), or the rows of a shared one that touch it; with ``data.keypoints``
   and ``data.cameras`` (the fusion of an online step) also its own keypoints file and its
   own camera, :func:`links_camera`; with ``data.weights`` its own links' evidence
   (:func:`links_weights`). Its own options
   (``options`` with its ``robot_options``). Public knowledge, as in the simulator: the team
   size ``n`` and the comm graph, of which it uses the edges that touch it.
2. **Its own features** (:func:`pipeline.matching.features.extract`, with the team's feature options:
   the photo defaults of ``run-images`` or the formations').
3. **Exchange for matching.** Matching of edge ``(i, j)`` is done by exactly one side, the
   lower id ``i``, so in round 0 a robot sends each *lower-id* neighbour its keypoints,
   descriptors (in compact form, :mod:`pipeline.matching.packed`; team option ``wire``
   ``plain``: as extracted, to every neighbour), intrinsics, image size and, when known, its
   pose (``features`` message, counted in bytes). The matching end uses
   the very function the simulator uses (:func:`pipeline.matching.pairs.match_pair`), then
   sends ``j`` the result (``matches``: pairs, ratios, epipolar errors and each link's local
   evidence, :func:`pipeline.matching.link_evidence.edge_evidence`). So both ends hold the same
   ``A_ij`` and the same evidence, equal to the simulator's for that edge.
4. **Feature counts** (every robot's ``m_j`` gives the column offsets of ``X_i·``: the
   blocks ``X_ij ∈ N^{m_i × m_j}`` of Sec. III, eq. 4, need them, though the paper also says
   the robots do not know ``m_sum`` in general, so they learn them here): flooded for
   ``n - 1`` rounds (``counts`` messages, only when a robot learnt something new), enough
   on any connected graph of ``n`` robots; with them a flag, whether some robot injects
   message loss (its own ``drop_prob``; a links team floods the flag alone,
   :func:`flood_flag`), which picks the rule (:func:`robot_resolution`). A links
   team whose robots read their own files: in the flag's first round the two ends of every
   link compare their rows of it and, for a rule that weighs links, its quality or weight
   (:func:`check_shared_links`; a link one file leaves out, or two values, is an InputError).
5. **Consistency** with local termination (:func:`pipeline.consistency.termination.
   run_consistency_locally`): detection, then Alg. 1 or the evidence rule
   (:func:`robot_resolution`), repeated until conflict-free.
6. **Fusion** (a rendered formation, or a links team given keypoints and cameras: robots that
   know their poses; team option ``fusion``):
   the robot's own part of robust distributed fusion (:mod:`pipeline.fusion.robot`) on the
   tracks it learnt in step 5 (:meth:`pipeline.consistency.robot.Robot.final_tracks`), ended
   by the termination wave; with message loss injected (``drop_prob``), every logical round
   over the reliable channel in lockstep (:func:`pipeline.fusion.robot_loops.run_fusion_reliably`). It cuts a link when exactly one
   of its ends is an observation declared an outlier (its own, or its neighbour's as the
   neighbour told it; a link between two outliers stays where the two can be one point:
   :mod:`pipeline.fusion.landmarks`,
   "Outliers leave the landmark"), and its links to a neighbour that fell silent during
   fusion (``robot-lost``).
7. **Publishes** its link table with every deletion (reason, round, iteration) and the fusion
   cuts (also in ``--result``, :func:`result_links`), the matches it holds, its keypoints and its fused landmarks (for the observer's
   evaluation only) and its counters.
"""

from __future__ import annotations

import os
import resource
import sys
import time
from pathlib import Path

import numpy as np

from pipeline.consistency.protocols import ProtocolOptions
from pipeline.consistency.robot import Robot
from pipeline.consistency.rules import DEFAULT_RESOLUTION, get_rule, rule_for_network
from pipeline.consistency.termination import robot_link_log, run_consistency_locally
from pipeline.errors import InputError
from pipeline.team.teamfile import (
    LAUNCHED_AT_ENV,
    PROFILE_DIR_ENV,
    keypoints_file_of,
    links_file_of,
    weights_file_of,
)
from pipeline.transport.wire import encode_packet, set_compression

__all__ = ["robot_main", "run_robot_process", "own_links_from_file", "robot_resolution",
           "flood_flag", "result_links", "load_view", "links_camera", "links_projection",
           "write_keypoints", "links_weights", "send_shared_links", "check_shared_links",
           "SHARED_LINKS"]


def _log(i: int, text: str) -> None:
    print(f"[robot {i}] {text}", file=sys.stderr, flush=True)


def peak_rss_bytes() -> int:
    """Peak resident set size of this process (Linux reports KiB)."""
    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) * 1024


def own_links_from_file(path, i: int, own_file: bool = False, rows: bool = False):
    """The rows of a links file that touch robot ``i``: ``(nbr, r, s, quality)`` arrays
    (``rows``: and each one's row index in the file, then whether the file has a quality
    column).

    ``own_file``: the file is robot ``i``'s own (``data.links`` lists one file per robot), so
    every row must touch it (InputError naming the first that does not: a file given to the
    wrong robot); otherwise the file is shared and the robot keeps its own rows.
    """
    from pipeline.inputs.linkscsv import read_links_csv

    lf = read_links_csv(path)
    L = lf.links
    a = np.flatnonzero(L.cam_i == i)
    b = np.flatnonzero(L.cam_j == i)
    if own_file and len(a) + len(b) < len(L):
        k = int(np.flatnonzero((L.cam_i != i) & (L.cam_j != i))[0])
        raise InputError(f"{path}:{lf.line[k]}: link ({L.cam_i[k]},{L.feat_i[k]})-"
                         f"({L.cam_j[k]},{L.feat_j[k]}) does not touch robot {i}, whose own "
                         "links file this is (data.links); give each robot the rows of its "
                         "own links")
    nbr = np.concatenate([L.cam_j[a], L.cam_i[b]])
    r = np.concatenate([L.feat_i[a], L.feat_j[b]])
    s = np.concatenate([L.feat_j[a], L.feat_i[b]])
    quality = np.concatenate([L.quality[a], L.quality[b]]).astype(np.float64)
    return (nbr, r, s, quality, np.concatenate([a, b]), bool(lf.has_quality)) if rows \
        else (nbr, r, s, quality)


def links_weights(team, i: int, n_rows: int) -> np.ndarray | None:
    """Robot ``i``'s link weights on a links team that gives them (``data.weights``: its own
    file, header ``weight``, one number per row of its own links file, in its order; ``inf``
    and ``-inf`` are numbers, as the simulator's link weights may be, ``nan`` is not), else
    None.

    Raises
    ------
    InputError
        Not that header, a row that is not one number (naming the line), or another
        count of rows than its links file holds.
    """
    import re

    from pipeline.inputs.csvfields import text_lines

    path = weights_file_of(team, i)
    if path is None:
        return None
    # the one reader of a user's text files: UTF-8 (else an error naming the line), a line of
    # bounded length, rows ending at \n or \r\n only
    lines = [line for _, line in text_lines(path, f"robot {i}'s weights file")]
    if not lines or lines[0].strip() != "weight":
        raise InputError(f"{path}:1: a weights file starts with the header weight")
    # digits 0-9 as a CSV writes them, or inf: Python's float() also takes "1_0" (10), other
    # scripts' digits and "nan"
    number = re.compile(r"[+-]?(([0-9]+\.?[0-9]*|\.[0-9]+)([eE][+-]?[0-9]+)?|inf|infinity)",
                        re.IGNORECASE)
    w = np.zeros(len(lines) - 1, np.float64)
    for k, line in enumerate(lines[1:]):
        if not number.fullmatch(line.strip()):
            raise InputError(f"{path}:{k + 2}: {line!r} is not a weight (one number, not nan)")
        w[k] = float(line)
    if len(w) != n_rows:  # the line of the first weight too many, or the one missing
        raise InputError(f"{path}:{min(len(w), n_rows) + 2}: {len(w)} weights for the "
                         f"{n_rows} rows of robot {i}'s links file; one weight per row, in "
                         "its order")
    return w


def write_keypoints(path, keypoints) -> None:
    """A keypoints file of a links team (``data.keypoints``): header ``x,y``, one row per
    feature, each coordinate as the shortest text that reads back to the same float32."""
    kp = np.asarray(keypoints, np.float32).reshape(-1, 2)
    with open(path, "w") as f:
        f.write("x,y\n" + "".join(f"{x!r},{y!r}\n" for x, y in kp.tolist()))


def links_camera(team, i: int):
    """Robot ``i``'s keypoints ``(m_i, 2)`` float32 and ``(K, R, t)`` on a links team that
    gives them (``data.keypoints``, ``data.cameras``), else ``(None, None)``. It reads its own
    keypoints file and its own camera entry only.

    Raises
    ------
    InputError
        The keypoints file is not ``x,y`` rows of finite numbers (naming the line), or holds
        another count of rows than ``data.features_per_camera`` gives robot ``i``.
    """
    path = keypoints_file_of(team, i)
    if path is None:
        return None, None
    from pipeline.inputs.csvfields import NUMBER, text_lines

    # the one reader of a user's text files: UTF-8 (else an error naming the line), a line of
    # bounded length, rows ending at \n or \r\n only
    lines = [line for _, line in text_lines(path, f"robot {i}'s keypoints file")]
    if not lines or lines[0].replace(" ", "") != "x,y":
        raise InputError(f"{path}:1: a keypoints file starts with the header x,y")
    kp = np.zeros((len(lines) - 1, 2), np.float64)
    for k, line in enumerate(lines[1:]):
        # digits 0-9 as a CSV writes them: Python's float() also takes "1_0" (10) and other
        # scripts' digits
        fields = [v.strip() for v in line.split(",")]
        xy = [float(v) for v in fields] if all(NUMBER.fullmatch(v) for v in fields) else []
        if len(xy) != 2 or not np.isfinite(xy).all():
            raise InputError(f"{path}:{k + 2}: {line!r} is not a keypoint x,y of two finite "
                             "numbers")
        kp[k] = xy
    m = int(team.data["features_per_camera"][i])
    if len(kp) != m:
        raise InputError(f"{path}: {len(kp)} keypoints, but data.features_per_camera gives "
                         f"robot {i} {m} features; one row per feature")
    cam = team.data["cameras"][i]
    if not (isinstance(cam, dict) and "K" in cam):  # a projection only, or no pose
        return kp.astype(np.float32), None
    return kp.astype(np.float32), (np.asarray(cam["K"], np.float64),
                                   np.asarray(cam["R"], np.float64),
                                   np.asarray(cam["t"], np.float64).reshape(3))


def links_projection(team, i: int):
    """Robot ``i``'s projection ``K [R | t]`` (3, 4) on a links team whose ``data.cameras``
    gives its pose or its projection ``P``, else None (its own entry only)."""
    cams = team.data.get("cameras")
    cam = None if cams is None else cams[i]
    if cam is None:
        return None
    if "P" in cam:
        return np.asarray(cam["P"], np.float64).reshape(3, 4)
    return np.asarray(cam["K"], np.float64) @ np.c_[np.asarray(cam["R"], np.float64),
                                                    np.asarray(cam["t"], np.float64).reshape(3)]


def load_view(team, i: int):
    """Robot ``i``'s own view: its rendered camera, or its photograph (downscaled to
    ``data.max_size``, with the intrinsics the team file gives it, ``intrinsics_source`` its
    ``data.intrinsics_source`` entry or ``team file``). An observer loads the photographs the
    same way (:mod:`pipeline.runs.observe`)."""
    data = team.data
    if data["kind"] == "formation":
        import data_synth

        view, _ = data_synth.render_robot(i, data.get("formation", "d"), int(data.get("seed", 0)),
                                          tuple(data.get("size", [640, 480])),
                                          data.get("robots"), data.get("graph"))
        return view
    if data["kind"] == "images":
        from pipeline.inputs.photos import downscale, guess_K, load_image
        from pipeline.types import View

        path = team.resolve_path(data["images"][i])
        pixels, header = load_image(path)
        header.close()
        # intrinsics are those of the image the robot uses (after max_size)
        K = (data.get("intrinsics") or [None] * team.n)[i]
        known = (data.get("intrinsics_known") or [K is not None] * team.n)[i]
        pixels, _ = downscale(pixels, np.eye(3), data.get("max_size"))
        h, w = pixels.shape[:2]
        K = guess_K(w, h) if K is None else np.asarray(K, np.float64)
        source = (data.get("intrinsics_source") or ["team file"] * team.n)[i]
        return View(name=path.name, image=pixels, K=np.asarray(K, np.float64),
                    intrinsics_known=bool(known), intrinsics_source=str(source))
    raise InputError(f"data kind {data['kind']!r} has no images")


def _pose(view):
    """``(K, R, t)`` of a view whose pose is known, else None."""
    if view.R is None or view.t is None:
        return None
    return (np.asarray(view.K, np.float64), np.asarray(view.R, np.float64),
            np.asarray(view.t, np.float64).reshape(3))


def _features_and_matches(team, i: int, transport, opts: dict, timings: dict):
    """Steps 1–4 of the module docstring.

    Returns ``(features, view, matches, weights, fpc, lossy)``: ``matches`` and ``weights``
    (the local evidence of each link, :func:`pipeline.matching.link_evidence.edge_evidence`,
    computed by the matching end and sent with the matches) per neighbour; ``lossy``: some
    robot of the team injects message loss (flooded with the counts, :func:`flood_flag`).
    """
    from pipeline.matching.link_evidence import edge_evidence
    from pipeline.matching.packed import (
        extract_raw,
        matching_descriptors,
        pack_features,
        unpack_features,
    )
    from pipeline.matching.pairs import match_pair
    from pipeline.stages import merge_radius_for
    from pipeline.types import Features, PairMatches

    # the merge radius of the rule asked for, as the simulator's matching takes it
    resolution = str(opts.get("resolution", DEFAULT_RESOLUTION))

    t = time.perf_counter()
    view = load_view(team, i)
    timings["load"] = time.perf_counter() - t
    t = time.perf_counter()
    h, w = view.image.shape[:2]
    # extracted without RootSIFT: the SIFT bytes travel, each end takes the root itself
    raw, rootsift = extract_raw(view, opts,
                                merge_radius_for(resolution, opts.get("merge_radius")))
    feats = Features(raw.keypoints, matching_descriptors(raw.descriptors, rootsift),
                     raw.scales, raw.method)
    timings["features"] = time.perf_counter() - t
    n = team.n
    known = np.full(n, -1, dtype=np.int32)
    known[i] = len(feats)
    lossy = np.array([_own_lossy(opts)], np.uint8)
    pose = _pose(view)
    compact = opts.get("wire", "compact") == "compact"
    payload = {**(pack_features(raw.keypoints, raw.descriptors, rootsift) if compact else
                  {"keypoints": feats.keypoints, "descriptors": feats.descriptors}),
               "K": np.asarray(view.K, np.float64),
               "intrinsics_known": np.array([view.intrinsics_known], np.uint8),
               "size": np.array([w, h], np.int32)}
    if pose is not None:  # a robot that knows its pose tells it (known-pose evidence)
        payload["R"], payload["t"] = pose[1], pose[2]
    del raw
    for k in sorted(transport.neighbours):
        if k < i or not compact:  # edge (k, i) is matched by k, the lower id: only k uses
            # these features (the plain encoding sends them to every neighbour)
            transport.send(k, "features", payload)
        transport.send(k, "counts", {"m": known.copy(), "lossy": lossy.copy()})
    sent, sent_lossy = known.copy(), lossy.copy()
    t = time.perf_counter()
    matches: dict[int, PairMatches] = {}
    weights: dict[int, np.ndarray] = {}
    rounds = max(n - 1, 2)
    for rnd in range(1, rounds + 1):
        inbox, _ = transport.end_round()
        for msg in inbox:
            p = msg.payload
            if msg.kind == "counts":
                upd = (known < 0) & (p["m"] >= 0)
                known[upd] = p["m"][upd]
                lossy |= p["lossy"]
            elif msg.kind == "features" and msg.src > i:
                kp_other, desc_other = unpack_features(p)
                other = Features(kp_other, desc_other, np.zeros(len(kp_other), np.float32),
                                 feats.method)
                both_known = bool(view.intrinsics_known and p["intrinsics_known"][0])
                thr = opts.get("threshold_px", 1.0)  # None: scaled with the larger image
                pm = match_pair(i, msg.src, feats, other, view.K, p["K"], both_known,
                                threshold_px=None if thr is None else float(thr),
                                matcher=opts.get("matcher", "opencv"),
                                sizes=((w, h), tuple(int(v) for v in p["size"])))
                other_pose = (p["K"], p["R"], p["t"]) if "R" in p else None
                ev = edge_evidence(pm, feats.keypoints, other.keypoints,
                                   pose if other_pose is not None else None, other_pose)
                matches[msg.src] = pm
                weights[msg.src] = ev.weight
                transport.send(msg.src, "matches", {
                    "pairs": pm.pairs.astype(np.int32), "ratio": pm.ratio.astype(np.float32),
                    "epipolar_error": pm.epipolar_error.astype(np.float32),
                    "weight": ev.weight.astype(np.float64),
                    "n_putative": np.array([pm.n_putative], np.int32),
                    "reason": np.frombuffer(pm.reason.encode(), np.uint8)})
            elif msg.kind == "matches":
                matches[msg.src] = PairMatches(
                    msg.src, i, p["pairs"].reshape(-1, 2), p["ratio"], p["epipolar_error"],
                    int(p["n_putative"][0]), bytes(p["reason"]).decode())
                weights[msg.src] = p["weight"]
        if rnd < rounds and ((known != sent).any() or (lossy != sent_lossy).any()):
            for k in sorted(transport.neighbours):
                transport.send(k, "counts", {"m": known.copy(), "lossy": lossy.copy()})
            sent, sent_lossy = known.copy(), lossy.copy()
    timings["matching_exchange"] = time.perf_counter() - t
    missing = sorted(k for k in transport.neighbours if k not in matches and k not in
                     getattr(transport, "silent", ()))
    if missing:
        raise RuntimeError(f"robot {i}: no matching with neighbour {missing[0]} after "
                           f"{rounds} rounds")
    fpc = np.where(known < 0, 0, known).astype(np.int64)
    return feats, view, matches, weights, fpc, bool(lossy[0])


def _own_lossy(opts: dict) -> bool:
    return float(opts.get("drop_prob", 0.0)) > 0


def flood_flag(transport, flag: bool, n: int, first_round=None) -> bool:
    """Whether any robot of a connected team of ``n`` holds ``flag``: each robot tells its
    neighbours its flag, then the OR it learnt whenever it grows, for ``n - 1`` rounds (every
    robot is within ``n - 1`` hops of every other on a connected graph). Used by robots that
    exchange no counts (a links file) to learn whether some robot injects message loss.

    ``first_round``: called with the inbox of the first round (the messages a caller sent
    before, :func:`send_shared_links`, ride in it: no round of their own)."""
    have = bool(flag)
    told = False
    for t in range(max(n - 1, 1)):
        if have and not told:
            for k in sorted(transport.neighbours):
                transport.send(k, "lossy", {"lossy": np.array([1], np.uint8)})
            told = True
        inbox, _ = transport.end_round()
        if t == 0 and first_round is not None:
            first_round(inbox)
        have = have or any(m.kind == "lossy" for m in inbox)
    return have


#: message kind of :func:`send_shared_links`
SHARED_LINKS = "shared-links"


def send_shared_links(transport, nbr, r, s, value=None) -> None:
    """Tell every neighbour the links this robot's own links file holds with it (``r`` its own
    feature, ``s`` the neighbour's) and, with ``value``, each one's quality or weight as read
    here (a ``shared-links`` message each, also when empty: a neighbour that lists links with
    this robot learns that it lists none). :func:`check_shared_links` compares them with the
    neighbour's own rows."""
    for k in sorted(transport.neighbours):
        sel = np.flatnonzero(nbr == k)
        payload = {"r": r[sel].astype(np.int32), "s": s[sel].astype(np.int32)}
        if value is not None:
            payload["value"] = np.asarray(value, np.float64)[sel]
        transport.send(k, SHARED_LINKS, payload)


def check_shared_links(i: int, inbox, nbr, r, s, value, what: str, where: dict) -> None:
    """Robot ``i``'s rows against the ``shared-links`` messages of its neighbours
    (:func:`send_shared_links`): every link the two ends share must be in both ends' files,
    with one ``what`` (``quality`` or ``weight``, compared when ``value`` is given).

    ``where``: the files the message names — ``own`` robot ``i``'s links file and
    ``own_values`` the file of its values (``its links file F``, ``its weights file W``),
    ``links`` and ``values`` the team file's keys of the neighbour's (``data.links``,
    ``data.weights``).

    Raises
    ------
    InputError
        Naming the first link (in robot ``i``'s table order) that one end lists and the
        other does not, or whose two ends give it different values; a ``sync`` team would
        otherwise run out of Borůvka rounds, and the other rules decide on one end's value.
    """
    def name(j, rr, ss):
        return f"robot {i}: link ({i},{int(rr)})-({int(j)},{int(ss)})"

    for msg in sorted((m for m in inbox if m.kind == SHARED_LINKS), key=lambda m: m.src):
        j, p = int(msg.src), msg.payload
        sel = np.flatnonzero(nbr == j)
        mine = (r[sel].astype(np.int64) << 32) | s[sel].astype(np.int64)
        theirs = (p["s"].astype(np.int64) << 32) | p["r"].astype(np.int64)
        order = np.argsort(theirs, kind="stable")
        theirs = theirs[order]
        pos = np.minimum(np.searchsorted(theirs, mine), max(theirs.size - 1, 0))
        found = (theirs[pos] == mine) if theirs.size else np.zeros(mine.size, bool)
        if not found.all():
            k = sel[int(np.flatnonzero(~found)[0])]
            raise InputError(f"{name(j, r[k], s[k])} is in {where['own']} but not in robot "
                             f"{j}'s ({where['links']}[{j}]); both ends of a link list it: "
                             "give both files every link the two robots share")
        extra = ~np.isin(theirs, mine)
        if extra.any():
            key = int(theirs[int(np.flatnonzero(extra)[0])])
            rr, ss = key >> 32, key & 0xFFFFFFFF
            raise InputError(f"{name(j, rr, ss)} is in robot {j}'s links file "
                             f"({where['links']}[{j}]) but not in {where['own']}; both ends of "
                             "a link list it: give both files every link the two robots share")
        if value is None or "value" not in p:
            continue
        mine_v = np.asarray(value, np.float64)[sel]
        theirs_v = p["value"][order][pos]
        bad = np.flatnonzero(mine_v != theirs_v)
        if bad.size:
            k, b = sel[int(bad[0])], int(bad[0])
            raise InputError(f"{name(j, r[k], s[k])} has {what} {float(mine_v[b])!r} in "
                             f"{where['own_values']} but {float(theirs_v[b])!r} in robot {j}'s "
                             f"({where['values']}[{j}]); give both ends the same {what}")


def _own_rows(i: int, matches: dict, weights: dict):
    """This robot's link table ``(nbr, r, s, weight)`` from the matches it holds."""
    nbr, r, s, w = [], [], [], []
    for k, pm in sorted(matches.items()):
        mine, theirs = (0, 1) if pm.i == i else (1, 0)
        nbr.append(np.full(len(pm.pairs), k, np.int64))
        r.append(pm.pairs[:, mine].astype(np.int64))
        s.append(pm.pairs[:, theirs].astype(np.int64))
        w.append(np.asarray(weights[k], np.float64).reshape(len(pm.pairs)))

    def cat(parts, dtype=np.int64):
        return np.concatenate(parts) if parts else np.zeros(0, dtype)

    return cat(nbr), cat(r), cat(s), cat(w, np.float64)


def robot_resolution(opts: dict, lossy: bool) -> str:
    """The rule the robots resolve by: the ``resolution`` option (the team's: a robot may not
    override it, :mod:`pipeline.team.teamfile`), except that with message loss injected at
    any robot (``lossy``, which every robot learns from its neighbours: :func:`flood_flag`,
    or with the feature counts) the fault-tolerant Alg. 1 runs, as the simulator does on a
    faulty network, instead of a rule that is not fault-tolerant. A robot reads only its own
    options."""
    return rule_for_network(str(opts.get("resolution", DEFAULT_RESOLUTION)), bool(lossy)).name


def robot_main(team, i: int, transport) -> tuple[dict, dict]:
    """Run robot ``i`` over ``transport`` (already connected); return (header, arrays).

    The header is JSON-able (counters, phases, timings); the arrays are the link log,
    keypoints and matches (see :func:`pipeline.consistency.termination.robot_link_log`).
    """
    if team.data["kind"] == "online-match":  # an online step's matching, nothing decided
        from pipeline.team.online_match import online_match_main

        return online_match_main(team, i, transport)
    opts = team.options_for(i)
    set_compression(opts.get("wire", "compact") == "compact")
    timings: dict = {}
    t0 = time.perf_counter()
    arrays: dict = {}
    matches_hdr = []
    keypoints, projection, pose = None, None, None
    has_quality = False  # a links file with a quality column
    if team.data["kind"] == "links":
        from pipeline.matching.link_evidence import ratio_llr

        fpc = np.asarray(team.data["features_per_camera"], dtype=np.int64)
        path, own_file = links_file_of(team, i)
        nbr, r, s, quality, rows, has_quality = own_links_from_file(path, i, own_file,
                                                                     rows=True)
        given = links_weights(team, i, len(rows)) if own_file else None
        bad = np.flatnonzero(~np.isin(nbr, list(transport.neighbours)))
        if bad.size:
            k = int(bad[0])
            raise InputError(f"robot {i}: link ({i},{int(r[k])})-({int(nbr[k])},{int(s[k])}) of "
                             f"{path} joins camera {int(nbr[k])}, which is not its neighbour in "
                             f"the team's comm_edges; add [{min(i, int(nbr[k]))}, "
                             f"{max(i, int(nbr[k]))}] to comm_edges or remove the link")
        bad = np.flatnonzero((r >= fpc[i]) | (s >= fpc[nbr]))
        if bad.size:
            k = int(bad[0])
            raise InputError(f"robot {i}: link ({i},{int(r[k])})-({int(nbr[k])},{int(s[k])}) of "
                             f"{path} names a feature beyond data."
                             f"features_per_camera ({int(fpc[i])} and {int(fpc[nbr[k]])}); "
                             "give counts that cover every feature id of the links file")
        # the evidence a links file carries: the weights given beside it (data.weights), else
        # the log-odds of its quality
        weight = ratio_llr(1.0 - quality) if given is None else given[rows]
        check = None
        if own_file:
            # each robot read its own file: the two ends of every link compare their rows (and,
            # for a rule that weighs links, the values) in the flag's first round
            value = (None if not get_rule(str(opts.get("resolution", DEFAULT_RESOLUTION)))
                     .needs_evidence else quality if given is None else given[rows])
            what = "quality" if given is None else "weight"
            wfile = weights_file_of(team, i)
            where = {"own": f"its links file {path}", "links": "data.links",
                     "own_values": (f"its links file {path}" if given is None
                                    else f"its weights file {wfile}"),
                     "values": "data.links" if given is None else "data.weights"}
            send_shared_links(transport, nbr, r, s, value)

            def check(inbox):
                try:
                    check_shared_links(i, inbox, nbr, r, s, value, what, where)
                except InputError as exc:
                    mismatch.append(exc)
        mismatch: list[InputError] = []
        lossy = flood_flag(transport, _own_lossy(opts), team.n, check)
        if mismatch:
            # stop only once the far end holds this robot's rows: it sends its round 1 packet
            # after its round 0 ended, which needed them. Stopping at once could close this
            # robot's session before its queued round 0 packet left, and the far end would
            # then see a robot lost rather than the mismatch (the flag's rounds after the
            # first give that round when there are two or more)
            if max(team.n - 1, 1) < 2:
                transport.end_round()
            raise mismatch[0]
        keypoints, pose = links_camera(team, i)
        projection = links_projection(team, i)
    else:
        feats, view, matches, weights, fpc, lossy = _features_and_matches(
            team, i, transport, opts, timings)
        nbr, r, s, weight = _own_rows(i, matches, weights)
        keypoints = feats.keypoints
        pose = _pose(view)
        if pose is not None:
            projection = pose[0] @ np.c_[pose[1], pose[2]]
        arrays["keypoints"] = feats.keypoints
        for k, pm in sorted(matches.items()):
            matches_hdr.append({"i": pm.i, "j": pm.j, "n_putative": pm.n_putative,
                                "reason": pm.reason})
            arrays[f"pairs_{k}"] = pm.pairs.astype(np.int32)
            arrays[f"ratio_{k}"] = pm.ratio.astype(np.float32)
            arrays[f"eperr_{k}"] = pm.epipolar_error.astype(np.float32)
    order = np.lexsort((s, nbr))  # the order of the Robot's link table
    robot = Robot(i, fpc, nbr[order], r[order], s[order])
    if has_quality:
        # the quality of each row of its link table, as its links file gives it: the
        # observer's links.csv keeps it (pipeline.runs.observe), as resolve's does
        arrays["link_quality"] = quality[order].astype(np.float64)
    wire = {"exchange": int(getattr(transport, "wire_bytes", 0))}
    resolution = robot_resolution(opts, lossy)
    rule = get_rule(resolution)
    if rule.needs_evidence:
        rule.hook("equip")(robot, weight[order],
                           np.zeros((robot.m, 2)) if keypoints is None else keypoints,
                           projection)
        if not bool(opts.get("solve_small_sets", True)):
            robot.evidence.solve_small = False  # the caller solves them (the online stage)
        if opts.get("bundle_budget") is not None:
            robot.evidence.bundle_budget = int(opts["bundle_budget"])
        if rule.set_lists:  # the small sets solved at their roots (pipeline.consistency.
            # roots), every robot alike
            robot.evidence.gather_conflictive = bool(opts.get("gather_conflictive", False))
            robot.evidence.gather_free = bool(opts.get("gather_free", False))
    if hasattr(transport, "status"):
        transport.status("consistency")
        transport.lossy = True  # faults are injected into the consistency stage, as simulated
    protocol = ProtocolOptions(reliable=True, loss_timeout=int(opts["loss_timeout"]))
    t = time.perf_counter()
    from pipeline.consistency.alone import LostInPhase

    restarted = bool(opts.get("restarted_on_loss", False))
    history, lost_in = None, None
    try:
        run = run_consistency_locally(robot, transport, protocol, team.n,
                                      resolution=resolution)
    except LostInPhase as exc:
        if not restarted:
            raise
        # the caller starts the team again: the robot says whom it lost and ends its work
        run, lost_in = exc.run, str(exc)
    if team.data.get("history") is not None and lost_in is None:  # an online step's check
        try:
            history = _robot_history(team, i, robot, transport, protocol, arrays)
        except LostInPhase as exc:
            if not restarted:
                raise
            run.lost_neighbours = sorted(set(run.lost_neighbours)
                                         | set(exc.run.lost_neighbours))
            lost_in = str(exc)
    if lost_in is not None:
        _log(i, f"{lost_in}: its team will be started again")
    timings["consistency"] = time.perf_counter() - t
    wire["consistency"] = int(getattr(transport, "wire_bytes", 0)) - sum(wire.values())
    fusion = None
    if bool(opts.get("fusion")) and pose is not None:
        t = time.perf_counter()
        fusion = _robot_fusion(team, i, robot, run, transport, keypoints, pose, arrays, lossy)
        timings["fusion"] = time.perf_counter() - t
        wire["fusion"] = int(getattr(transport, "wire_bytes", 0)) - sum(wire.values())
    timings["total"] = time.perf_counter() - t0
    arrays.update(robot_link_log(robot))
    header = {"id": i, "features_per_camera": fpc.tolist(), "matches": matches_hdr,
              "resolution": resolution,
              "counters": transport.counters(), "wire_bytes_by_stage": wire, "run": {k: v for k, v in vars(run).items()},
              "peak_memory_bytes": int(robot.peak_memory_bytes), "timings_s": timings,
              "peak_rss_bytes": peak_rss_bytes(), "pid": os.getpid(), "fusion": fusion,
              "history": history}
    return header, arrays


def _robot_history(team, i: int, robot, transport, protocol, arrays: dict) -> dict:
    """The history check of an online step after the rule (:mod:`pipeline.consistency.
    history`), on the robot's own inputs (its file of ``data.history``); the links it cuts go
    to ``arrays['history_cut']``. Returns its rounds and phases."""
    from pipeline.consistency.alone import run_history_locally

    equip_history_file(robot, team.resolve_path(team.data["history"][i]), i)
    hrun = run_history_locally(robot, transport, protocol, team.n)
    arrays["history_cut"] = np.asarray(sorted(robot.history.cut), np.int64)
    return {"rounds": int(hrun.detection_rounds + hrun.resolution_rounds),
            "phases": hrun.phases}


def _history_where(path, i: int) -> str:
    return f"robot {i}: data.history[{i}] {path}"


_HISTORY_WRITER = "the online stage writes one per robot (pipeline.runs.transports.zenoh.online_stage)"

#: the arrays of a history file by group (the arrays of a group have one length each) and
#: what each holds: ``"id"`` whole numbers >= 0, ``"id-1"`` whole numbers >= -1 (a row's link
#: id, -1: a history link), ``"quality"`` finite numbers, ``"flag"`` true/false values
_HISTORY_ARRAYS = {
    "row": {"row_nbr": "id", "row_s": "id", "row_id": "id-1", "row_quality": "quality",
            "row_hist": "flag"},
    "border": {"border_r": "id", "border_piece": "id", "border_id": "id",
               "border_quality": "quality", "border_head": "flag"},
    "entry": {"entry_piece": "id", "entry_robot": "id", "entry_lo": "id", "entry_hi": "id"},
}
_HISTORY_WHAT = {"id": "whole numbers >= 0", "id-1": "whole numbers >= -1 (-1: a history link)",
                 "quality": "finite numbers", "flag": "true/false values"}


def _history_array_ok(a: np.ndarray, what: str) -> bool:
    """Whether ``a`` (1-D) holds what ``what`` says (:data:`_HISTORY_ARRAYS`)."""
    if a.size == 0:  # an empty array of any plain kind (np.array([]) is float64)
        return a.dtype.kind in "biuf"
    if what == "flag":
        return a.dtype.kind == "b"
    if what == "quality":
        return a.dtype.kind in "iuf" and bool(np.isfinite(a).all())
    if a.dtype.kind not in "iu":
        return False
    lo = -1 if what == "id-1" else 0
    return bool(a.min() >= lo) and int(a.max()) <= np.iinfo(np.int64).max


def _checked_history_arrays(f: dict, where: str) -> dict:
    """The arrays of a history file (by name), after checking each one's shape, dtype and
    values and the lengths of each group (:data:`_HISTORY_ARRAYS`); InputError naming the
    array otherwise."""
    missing = [k for k in ("head", *(k for g in _HISTORY_ARRAYS.values() for k in g))
               if k not in f]
    if missing:
        raise InputError(f"{where} is not a history file of an online step: it has no array "
                         f"{missing[0]!r}; {_HISTORY_WRITER}")
    out = {}
    head = f["head"]
    if head.shape != (3,) or head.dtype.kind not in "iu" or (head < 0).any():
        shown = head.tolist() if head.size <= 6 else f"an array of shape {head.shape}"
        raise InputError(f"{where}: head {shown} ({head.dtype}) is not three whole numbers >= 0 "
                         f"(first global id, robot, step); {_HISTORY_WRITER}")
    out["head"] = head
    for group, names in _HISTORY_ARRAYS.items():
        length = None
        for k, what in names.items():
            a = f[k]
            if a.ndim != 1 or not _history_array_ok(a, what):
                shape = f"shape {a.shape}, dtype {a.dtype}"
                raise InputError(f"{where}: array {k!r} ({shape}) is not a list of "
                                 f"{_HISTORY_WHAT[what]}; {_HISTORY_WRITER}")
            if length is None:
                length, first = len(a), k
            elif len(a) != length:
                raise InputError(f"{where}: array {k!r} has {len(a)} entries, {first!r} "
                                 f"{length}: the {group} arrays go together, one entry each; "
                                 f"{_HISTORY_WRITER}")
            out[k] = a
    return out


def load_history_inputs(path, i: int):
    """Robot ``i``'s inputs of an online step's history check from its file (``data.history``
    of the team file, :class:`pipeline.consistency.history.HistoryInputs` as named arrays).

    Raises
    ------
    InputError
        Naming the file: not a NumPy ``.npz`` archive (or one holding pickled objects), an
        array missing; naming the array: ``head`` not three whole numbers >= 0; a row,
        border or entry array not 1-D, of another kind than it holds (link ids, feature ids,
        pieces, robots, steps: whole numbers >= 0, a row's link id >= -1; qualities: finite
        numbers; ``row_hist``, ``border_head``: true/false values), or of another length
        than the first array of its group.
    """
    from pipeline.consistency.history import HistoryInputs
    from pipeline.inputs.npzfile import npz_arrays

    where = _history_where(path, i)
    try:
        arrays = npz_arrays(path)
    except ValueError as e:
        raise InputError(f"{where} is not a history file of an online step ({e}); "
                         f"{_HISTORY_WRITER}") from e
    return HistoryInputs.from_arrays(_checked_history_arrays(arrays, where))


def equip_history_file(robot, path, i: int) -> None:
    """Give ``robot`` (robot ``i``) its inputs of the history check from its file
    (:func:`load_history_inputs`); InputError naming the file when they do not fit its link
    table (a row it does not hold, a row of it left out) or name a feature it does not have
    (``border_r``)."""
    from pipeline.consistency.history import equip_history
    from pipeline.progress import counted

    inp = load_history_inputs(path, i)
    where = _history_where(path, i)
    br = np.asarray(inp.border_r)
    if br.size and int(br.max()) >= robot.m:
        raise InputError(f"{where}: array 'border_r' names feature {int(br.max())}, robot {i} "
                         f"has {counted(robot.m, 'feature')}; {_HISTORY_WRITER}")
    nbr, s_ = np.asarray(inp.row_nbr, np.int64), np.asarray(inp.row_s, np.int64)
    pos = robot.find_links(nbr, s_)
    if (pos < 0).any():
        k = int(np.flatnonzero(pos < 0)[0])
        raise InputError(f"{where}: row {k} (arrays 'row_nbr', 'row_s': neighbour {nbr[k]}, "
                         f"its feature {s_[k]}) is no link of robot {i}; {_HISTORY_WRITER}")
    if len(np.unique(pos)) != len(pos) or len(pos) != len(robot.link_key):
        raise InputError(f"{where}: arrays 'row_nbr', 'row_s' name {counted(len(pos), 'row')} "
                         f"({counted(len(np.unique(pos)), 'link')} of robot {i}), its link "
                         f"table holds {counted(len(robot.link_key), 'link')}, one row each; "
                         f"{_HISTORY_WRITER}")
    equip_history(robot, inp)


def _robot_fusion(team, i: int, robot, run, transport, keypoints, pose, arrays: dict,
                  lossy: bool) -> dict:
    """Step 6 of the module docstring; fills ``arrays`` and returns the header's ``fusion``."""
    from pipeline.consistency.protocols import ProtocolOptions
    from pipeline.consistency.robot import ROBOT_LOST
    from pipeline.fusion.robot import FusionRobot
    from pipeline.fusion.robot_loops import run_fusion_locally, run_fusion_reliably

    if hasattr(transport, "status"):
        transport.status("fusion")
    K, R, t = pose
    # its own neighbourhood: the comm edges that touch it, in the team's order
    e = np.asarray(team.comm_edges, dtype=np.int64).reshape(-1, 2)
    own_edges = e[(e[:, 0] == i) | (e[:, 1] == i)]
    labels = robot.final_tracks()
    fusion = FusionRobot(i, team.n, own_edges, labels, keypoints, K, R, t)
    if lossy:
        # loss injected (learnt with the counts): every logical round over the reliable
        # channel in lockstep, as the simulator's fusion runs on a lossy network
        out = run_fusion_reliably(fusion, transport, ProtocolOptions(
            reliable=True, loss_timeout=int(team.options_for(i)["loss_timeout"])), team.n)
    else:
        out = run_fusion_locally(fusion, transport, team.n)
    if out["lost"]:
        gone = np.flatnonzero(robot.link_alive & np.isin(robot.link_nbr, out["lost"]))
        robot.delete_links(gone, transport.round, ROBOT_LOST)
        run.lost_neighbours = sorted(set(run.lost_neighbours) | set(out["lost"]))
    cut = fusion.cut_rows(robot.link_nbr, robot.link_r, robot.link_s) & robot.link_alive
    arrays["fusion_cut"] = cut.astype(np.uint8)
    arrays["fusion_names"] = fusion.names.astype(np.int64)
    arrays["fusion_feat"] = fusion.feat.astype(np.int32)
    arrays["fusion_theta"] = np.asarray(fusion.theta_w, np.float64).reshape(-1, 3)
    arrays["fusion_valid"] = np.asarray(fusion.ok_w, np.uint8)
    arrays["fusion_estimated"] = np.asarray(fusion.est, np.uint8)
    arrays["fusion_inlier"] = np.asarray(fusion.yes_w, np.uint8)
    arrays["fusion_outlier"] = np.asarray(fusion.outlier, np.uint8)
    arrays["fusion_winner"] = np.asarray(fusion.winner, np.int32)
    # the track names fusion started from (conflictive ones too): the observer counts the
    # stage's tracks and observations from them, as the simulator does from the same names
    arrays["fusion_labels"] = np.asarray(labels, np.int64)
    opt = fusion.opt
    return {**out, "tracks": int(len(fusion.names)), "estimated": int(fusion.est.sum()),
            "outliers": int(len(fusion.outlier_feats)), "links_cut": int(cut.sum()),
            "hypotheses": int(fusion.Kh), "consensus": fusion.opt.consensus,
            "noise": fusion.opt.noise, "sigma_px": fusion.sigma,
            "noise_residuals": int(fusion.noise_residuals),
            "options": {"c": int(opt.c), "local": opt.local, "gate": opt.gate,
                        "p": float(opt.p), "sigma_px": float(opt.sigma_px), "wire": opt.wire,
                        # W of the Metropolis stop rule (the exact mode has none)
                        "stop_window": int(fusion.W) if opt.consensus == "metropolis" else None},
            "forced": _forced(fusion)}


def result_links(arrays: dict) -> dict:
    """Every decision the robot made on each row of its link table, for ``--result``: the
    link (``link_nbr``, ``link_r``, ``link_s``), its deletion log (``link_alive`` after the
    consistency stage, ``deleted_case``, ``deleted_round``, ``deleted_iteration``), the
    fusion stage's cut (``fusion_cut``, 0 without fusion) and the outcome as the run's
    ``links.csv`` words it: ``status`` ``kept``/``deleted`` and ``reason`` (the case of
    :func:`pipeline.consistency.rules.case_names` — ``b``, ``c``, ``reject``, ``robot-lost``,
    a rule's own — or ``fusion-outlier``; empty when kept)."""
    from pipeline.consistency.robot import CASE_NAMES
    from pipeline.consistency.rules import case_names

    names = {**CASE_NAMES, **case_names()}
    alive = arrays["link_alive"].astype(bool)
    cut = arrays.get("fusion_cut", np.zeros(len(alive), np.uint8)).astype(bool) & alive
    reason = [("fusion-outlier" if c else "") if a else names.get(int(k), str(int(k)))
              for a, c, k in zip(alive.tolist(), cut.tolist(), arrays["deleted_case"].tolist(),
                                 strict=True)]
    out = {k: arrays[k].tolist() for k in ("link_nbr", "link_r", "link_s", "link_alive",
                                           "deleted_case", "deleted_round",
                                           "deleted_iteration")}
    out["fusion_cut"] = cut.astype(np.uint8).tolist()
    out["status"] = ["kept" if a and not c else "deleted"
                     for a, c in zip(alive.tolist(), cut.tolist(), strict=True)]
    out["reason"] = reason
    return out


def _forced(fusion) -> bool:
    """True when, in the exact mode, this robot decided a track by the round cap before its
    ball closed (the simulator's ``settled`` false); False otherwise."""
    flood = getattr(fusion, "flood", None)
    if flood is None:
        return False
    return any(bool(st.forced) for st in flood.tracks.values())


def _since_launch() -> float | None:
    """Seconds since the launcher started this process (None when started by hand)."""
    try:
        return round(time.time() - float(os.environ[LAUNCHED_AT_ENV]), 4)
    except (KeyError, ValueError):
        return None


def _profiled(main, team, i: int, transport):
    """``main(team, i, transport)``, under cProfile when :data:`PROFILE_DIR_ENV` names a
    folder (its statistics written there as ``<team>-<i>-<pid>.pstats``, also on failure)."""
    folder = os.environ.get(PROFILE_DIR_ENV)
    if not folder:
        return main(team, i, transport)
    import cProfile

    prof = cProfile.Profile()
    try:
        return prof.runcall(main, team, i, transport)
    finally:
        Path(folder).mkdir(parents=True, exist_ok=True)
        prof.dump_stats(str(Path(folder) / f"{team.name}-{i}-{os.getpid()}.pstats"))


def run_robot_process(team, i: int, result_path=None, overwrite: bool = False) -> int:
    """The ``robot`` command: connect, handshake, run, publish; returns an exit code.

    ``result_path`` (``--result``) is replaced only with ``overwrite``, also when it appeared
    while the robot ran (another process given the same file). A result that cannot be
    written is one ``error:`` line and exit 2, after the result was published to the team's
    observer all the same."""
    startup = {"entered": _since_launch()}
    from pipeline.transport.zenoh_transport import ZenohTransport

    opts = team.options_for(i)
    transport = ZenohTransport(team, i, drop_prob=float(opts["drop_prob"]),
                               seed=int(opts["fault_seed"]),
                               round_timeout_s=float(opts["round_timeout_s"]),
                               round_limit_s=float(opts["round_limit_s"]),
                               shared_memory=bool(opts["shared_memory"]),
                               log=lambda s: _log(i, s))
    startup["session_open"] = _since_launch()
    try:
        transport.status("started")
        try:
            # an online step's matching robot has its own frame to publish without neighbours
            waited = transport.handshake(float(opts["start_timeout_s"]),
                                         alone=team.data.get("kind") == "online-match",
                                         closed_unheard=bool(opts["closed_at_start"]))
        except InputError as exc:  # another team file than a neighbour's
            transport.status(f"failed: {exc}")
            raise
        startup["handshake_done"] = _since_launch()
        gone = sorted(k for k in transport.neighbours if k in transport.written_off)
        heard = len(transport.neighbours) - len(gone)
        _log(i, (f"all {heard} neighbours heard" if not gone else
                 f"{heard} of {len(transport.neighbours)} neighbours heard, "
                 f"{', '.join(map(str, gone))} written off") + f" after {waited:.2f} s")
        try:
            header, arrays = _profiled(robot_main, team, i, transport)
        except Exception as exc:
            transport.status(f"failed: {exc}")
            raise
        header["handshake_s"] = round(waited, 4)
        header["team_terms"] = team.shared_terms()  # the observer checks its own file's
        startup["main_done"] = _since_launch()
        # seconds from the launcher's start of this process to each step (profile of the
        # process start; None when the robot was started by hand)
        header["since_launch_s"] = startup
        if "link_alive" in arrays:
            kept = int(arrays["link_alive"].sum())
            _log(i, f"links: {kept} kept, {len(arrays['link_alive']) - kept} deleted of "
                    f"{len(arrays['link_alive'])}")
        unwritten = None
        if result_path and "link_alive" in arrays:
            from pipeline.runfolder import note_output_in_place, write_json_atomic

            try:
                write_json_atomic(result_path, {**header, "links": result_links(arrays)},
                                  replace=overwrite, flag="--result")
            except (InputError, OSError) as exc:  # published all the same, below
                unwritten = exc
            else:  # a Ctrl-C while the observer is awaited names it as written
                note_output_in_place(result_path)
        # repeated until the observer acknowledges it: an observer started by hand may come
        # up while the robots run, so wait as long as for a neighbour at the start
        acked = transport.publish_result(encode_packet(header, [("result", arrays)]),
                                         wait_s=max(10.0, float(opts["start_timeout_s"])))
        _log(i, f"outcome: {header['counters']['outcome']}"
                f"{'' if not transport.written_off else f' {transport.written_off}'}")
        _log(i, f"done in {header['timings_s']['total']:.2f} s, {transport.round} rounds"
                f"{'' if acked or not team.observer else ' (observer did not acknowledge)'}")
        # the last round's packets were handed to Zenoh before the result, and closing the
        # session drains what it still queues; a short pause covers a slow neighbour link
        time.sleep(0.05)
    finally:
        transport.close()
    if unwritten is not None:
        print(f"error: robot {i}: {unwritten}", file=sys.stderr, flush=True)
        return 2
    return 0
