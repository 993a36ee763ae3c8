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
    if np.any(np.diff(msg.names) <= 0):
        raise ValueError("a flood message lists its tracks in increasing name order")
    names = msg.names.tolist()
    last, count = np.asarray(msg.last, bool), np.asarray(msg.count, np.int64)
    dt = WIRE_DTYPES[wire]
    ib = np.dtype(f"u{index_bytes(n)}")
    e = msg.entries
    if e is not None and len(e):
        robot, nbrs, est = e.robot, e.neighbours.reshape(-1, n), e.estimated.astype(bool)
        draws = e.draws.reshape(len(e), -1)[est]
        x = e.x.reshape(-1, 3)[est]
        info = e.info.reshape(-1, 3, 3)[est][:, TRIU[0], TRIU[1]]
    else:
        robot, nbrs, est = np.zeros(0, np.int64), np.zeros((0, n), bool), np.zeros(0, bool)
        draws, x, info = np.zeros((0, 0)), np.zeros((0, 3)), np.zeros((0, 6))
    if not est.any():
        draws = np.zeros((0, 0))
    out = {"count": count.astype(np.dtype(f"u{index_bytes(n + 1)}")), "last": np.packbits(last),
           "robot": robot.astype(ib), "nbrs": np.packbits(nbrs, axis=1),
           "flags": est.astype(np.uint8), "draws": draws.astype(np.float64),
           "x": x.astype(dt), "info": info.astype(dt)}
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
    from pipeline.fusion.flood_robot import FloodEntries, FloodMessage

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
    robot = p["robot"].astype(np.int64)
    draws = np.full((E, K), -np.inf)
    x, info = np.zeros((E, 3)), np.zeros((E, 3, 3))
    if est.any():
        draws[est] = p["draws"].astype(np.float64)
        x[est] = p["x"].astype(np.float64)
        tri = p["info"].astype(np.float64)
        full = np.zeros((tri.shape[0], 3, 3))
        full[:, TRIU[0], TRIU[1]] = tri
        full[:, TRIU[1], TRIU[0]] = tri
        info[est] = full
    msg = FloodMessage(src, dst, round_, names=np.asarray(names, dtype=np.int64).reshape(-1),
                       last=last, count=count,
                       entries=FloodEntries(robot, nbrs, est, draws, x, info))
    shared = list(shared)
    for t, (a_, b_) in zip(p.get("tomb_track", []), p.get("tomb_ends", np.zeros((0, 2))),
                           strict=True):
        msg.down.setdefault(int(shared[int(t)]), []).append((int(a_), int(b_)))
    return msg
