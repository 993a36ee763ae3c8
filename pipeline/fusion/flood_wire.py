"""The exact consensus on the wire: a robot's flood messages (:mod:`pipeline.fusion.flood_robot`)
as named arrays, byte for byte the layout :mod:`pipeline.fusion.flooding` counts, and back.
"""

from __future__ import annotations

import numpy as np

from pipeline.fusion.protocol import (
    WIRE_DTYPES,
    index_bytes,
)

__all__ = ["encode_flood", "decode_flood", "TRIU"]

#: the upper triangle of a 3 x 3 symmetric matrix, the part that travels
TRIU = np.triu_indices(3)


def encode_flood(msg, n: int, wire: str, shared, named: bool = False) -> dict:
    """A :class:`~pipeline.fusion.flood_robot.FloodMessage` as named arrays, byte for byte the
    layout :mod:`pipeline.fusion.flooding` counts: per open track (in name order; both ends
    know which tracks are open on the link) its entry count and a bit of a *last* bitmap; per
    entry the robot id, its neighbour bitmap and a flags byte (it carries an observation); per
    estimated entry its ``K`` draws (float64), ``x_i`` and the upper triangle of ``Λ_i⁻¹`` at
    the wire's precision (``Λ_i⁻¹`` is exactly symmetric); per tombstone the track's position
    among the link's ``shared`` tracks (sorted names) and the two ends of the lost link.
    ``named``: the open tracks' names are sent too (8 bytes each), which a robot does once it
    has seen a lost link, when tombstones may reopen a track the other end considers closed."""
    names = sorted(msg.tracks)
    last = np.array([bool(msg.tracks[b][0]) for b in names], dtype=bool)
    ents = [e for b in names for e in msg.tracks[b][1]]
    count = np.array([len(msg.tracks[b][1]) for b in names], dtype=np.int64)
    E = [e for e in ents if e.estimated]
    dt = WIRE_DTYPES[wire]
    K = len(E[0].draws) if E else 0
    ib = np.dtype(f"u{index_bytes(n)}")
    out = {"count": count.astype(np.dtype(f"u{index_bytes(n + 1)}")), "last": np.packbits(last),
           "robot": np.array([e.robot for e in ents], dtype=ib),
           "nbrs": np.packbits(np.array([e.neighbours for e in ents], dtype=bool).reshape(
               len(ents), n), axis=1),
           "flags": np.array([bool(e.estimated) for e in ents], dtype=np.uint8),
           "draws": np.array([e.draws for e in E], dtype=np.float64).reshape(len(E), K),
           "x": np.array([e.x for e in E], dtype=dt).reshape(len(E), 3),
           "info": np.array([np.asarray(e.info)[TRIU] for e in E], dtype=dt).reshape(len(E), 6)}
    if named:
        out["names"] = np.asarray(names, dtype=np.int64)
    tomb = [(b, a_, b_) for b in sorted(msg.down) for a_, b_ in msg.down[b]]
    if tomb:
        pos = np.searchsorted(np.asarray(shared, dtype=np.int64), [t[0] for t in tomb])
        out["tomb_count"] = np.array([len(tomb)], dtype=np.uint32)
        out["tomb_track"] = pos.astype(np.uint32)
        out["tomb_ends"] = np.array([t[1:] for t in tomb], dtype=ib).reshape(len(tomb), 2)
    return out


def decode_flood(src: int, dst: int, round_: int, names, p: dict, n: int, K: int, shared=()):
    """Inverse of :func:`encode_flood`, given the names of the open tracks (in order) unless
    the message names them, and the link's shared tracks (sorted names, for tombstones)."""
    from pipeline.fusion.flood_robot import FloodEntry, FloodMessage

    if "names" in p:
        names = [int(b) for b in p["names"]]
    count = p["count"].astype(np.int64)
    if len(count) != len(names):
        raise RuntimeError(f"robot {dst}: a fusion message of robot {src} carries "
                           f"{len(count)} tracks, {len(names)} are open on the link")
    last = np.unpackbits(p["last"], count=len(names)).astype(bool)
    E = int(count.sum())
    est = p["flags"].astype(bool)
    nbrs = np.unpackbits(p["nbrs"], axis=1, count=n).astype(bool) if E else \
        np.zeros((0, n), bool)
    pos = np.cumsum(est) - 1
    msg = FloodMessage(src, dst, round_)
    k = 0
    for b, lb, c in zip(names, last, count, strict=True):
        entries = []
        for _ in range(int(c)):
            if est[k]:
                e = int(pos[k])
                info = np.zeros((3, 3))
                info[TRIU] = p["info"][e].astype(np.float64)
                info[TRIU[1], TRIU[0]] = p["info"][e].astype(np.float64)
                entries.append(FloodEntry(int(p["robot"][k]), nbrs[k], True,
                                          p["draws"][e].astype(np.float64),
                                          p["x"][e].astype(np.float64), info))
            else:
                entries.append(FloodEntry(int(p["robot"][k]), nbrs[k], False,
                                          np.full(K, -np.inf), np.zeros(3), np.zeros((3, 3))))
            k += 1
        msg.tracks[int(b)] = (bool(lb), entries)
    shared = list(shared)
    for t, (a_, b_) in zip(p.get("tomb_track", []), p.get("tomb_ends", np.zeros((0, 2))),
                           strict=True):
        msg.down.setdefault(int(shared[int(t)]), []).append((int(a_), int(b_)))
    return msg
