"""Camera and feature ids of a user's links file, made compact when they are sparse.

The consistency stage lays features out by id (feature ``r`` of camera ``i`` is global id
``offset[i] + r``, docs/DESIGN.md "Conventions") and every robot knows every ``m_i``, so its
memory follows the *largest* camera and feature ids, not the links. A links file is not a
matcher's output: its ids may be anything, and one line ``2147483646,0,0,0`` would ask for
two billion cameras.

Rule (:func:`compact_ids`): the ids are used as given (``m_i = max feature id + 1``,
``n = max camera id + 1``) while that layout is small — at most :data:`DENSE_CAMERAS`
cameras and :data:`DENSE_FEATURES` features in all, or at most
``DENSE_PER_LINK_END`` features per link end. Beyond that, cameras are renumbered to the ones
that appear in a link or a comm edge and features, per camera, to the ones that appear in a
link, both in increasing order. Every order the algorithms use (camera ids, global feature
ids) is kept, so Alg. 1's cuts, reasons, rounds and cases are the same either way; the merge
rules (sync, evidence) order links of equal evidence by a hash of their global ids
(:func:`pipeline.consistency.keys.tie_key`), which renumbering changes, so ``resolve`` always
runs on the compact layout (one layout however the ids are spelled, on every transport). Results are per link, so nothing needs
mapping back except robot ids in the fault report (:meth:`CompactIds.robot_ids`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.types import Links

__all__ = ["DENSE_CAMERAS", "DENSE_FEATURES", "DENSE_PER_LINK_END", "CompactIds", "compact_ids"]

DENSE_CAMERAS = 1 << 16
DENSE_FEATURES = 1 << 22
DENSE_PER_LINK_END = 16


@dataclass
class CompactIds:
    """The ids the consistency stage runs on, and the way back.

    Attributes
    ----------
    compacted : bool — the ids were renumbered (else everything is as given)
    cameras : (n,) int64 — original id of each camera the stage runs on
    links : Links — the links in the ids the stage runs on
    features_per_camera : (n,) int64
    edges : (E, 2) int64 or None — the comm edges in those ids
    """

    compacted: bool
    cameras: np.ndarray
    links: Links
    features_per_camera: np.ndarray
    edges: np.ndarray | None

    def robot_index(self, camera: int) -> int | None:
        """Robot (camera) number in the stage of original camera id ``camera``; None if absent."""
        k = int(np.searchsorted(self.cameras, camera))
        return k if k < len(self.cameras) and self.cameras[k] == camera else None

    def robot_ids(self, robots) -> list[int]:
        """Original camera ids of stage robots ``robots``."""
        return [int(self.cameras[int(r)]) for r in robots]


def _dense_size(links: Links, edges: np.ndarray | None) -> tuple[int, int]:
    """``(n, m_total)`` of the as-given layout, computed without allocating it."""
    cams = np.concatenate([links.cam_i, links.cam_j])
    feats = np.concatenate([links.feat_i, links.feat_j])
    n = int(cams.max(initial=-1)) + 1
    if edges is not None and edges.size:
        n = max(n, int(edges.max()) + 1)
    if not cams.size:
        return n, 0
    order = np.lexsort((feats, cams))
    last = np.flatnonzero(np.r_[cams[order][1:] != cams[order][:-1], True])
    return n, int((feats[order][last] + 1).sum())


def _ranks(values: np.ndarray, table: np.ndarray) -> np.ndarray:
    return np.searchsorted(table, values)


def compact_ids(links: Links, edges: np.ndarray | None = None, force: bool | None = None,
                n_cameras: int | None = None) -> CompactIds:
    """The layout the consistency stage runs on (module rule).

    Parameters
    ----------
    links : Links, (L,) — validated (ids >= 0, ``cam_i < cam_j``)
    edges : (E, 2) int or None — comm edges in the same camera ids
    force : True / False to compact / not regardless of the rule (tests)
    n_cameras : as-given camera count to keep when not compacting (e.g. from a comm graph)

    Returns
    -------
    CompactIds
    """
    e = None if edges is None else np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    n, m_total = _dense_size(links, e)
    if n_cameras is not None:
        n = max(n, int(n_cameras))
    small = n <= DENSE_CAMERAS and (m_total <= DENSE_FEATURES
                                    or m_total <= DENSE_PER_LINK_END * 2 * len(links))
    if not (force if force is not None else not small):
        m = np.zeros(n, dtype=np.int64)
        np.maximum.at(m, links.cam_i, links.feat_i + 1)
        np.maximum.at(m, links.cam_j, links.feat_j + 1)
        return CompactIds(False, np.arange(n, dtype=np.int64), links, m, e)
    cams = np.unique(np.concatenate([links.cam_i, links.cam_j]
                                    + ([e.ravel()] if e is not None else [])))
    ci, cj = _ranks(links.cam_i, cams), _ranks(links.cam_j, cams)
    # per camera, the feature ids present, in order: rank of (camera, feature) among them
    key_cam = np.concatenate([ci, cj])
    key_feat = np.concatenate([links.feat_i, links.feat_j])
    order = np.lexsort((key_feat, key_cam))
    kc, kf = key_cam[order], key_feat[order]
    new_run = np.ones(kc.size, dtype=bool)
    new_run[1:] = (kc[1:] != kc[:-1]) | (kf[1:] != kf[:-1])
    uniq_id = np.cumsum(new_run) - 1                       # index among unique (cam, feat)
    first_of_cam = np.ones(kc.size, dtype=bool)
    first_of_cam[1:] = kc[1:] != kc[:-1]
    cam_start = np.maximum.accumulate(np.where(first_of_cam, uniq_id, 0))
    rank = np.empty_like(uniq_id)
    rank[order] = uniq_id - cam_start
    L = len(links)
    m = np.zeros(len(cams), dtype=np.int64)
    np.maximum.at(m, kc, uniq_id - cam_start + 1)
    clinks = Links(ci, rank[:L], cj, rank[L:], links.quality)
    cedges = None if e is None else _ranks(e, cams).reshape(-1, 2)
    return CompactIds(True, cams.astype(np.int64), clinks, m, cedges)


def faults_in_layout(faults, ids: CompactIds):
    """``faults`` with its crashed robots renumbered like ``ids`` (InputError: no such robot)."""
    import dataclasses

    from pipeline.errors import InputError

    if not ids.compacted or not faults.crash:
        return faults
    crash = []
    for r, t in faults.crash:
        k = ids.robot_index(int(r))
        if k is None:
            raise InputError(f"--crash {r}@{t}: robot {r} does not exist; robots are the "
                             "cameras named in the links or the comm graph")
        crash.append((k, int(t)))
    return dataclasses.replace(faults, crash=tuple(crash))


def fault_section_in_ids(section: dict, ids: CompactIds) -> dict:
    """A :func:`pipeline.faults.fault_report` section with robot numbers made original ids."""
    if not ids.compacted:
        return section
    out = dict(section)

    def cam(k):
        return str(ids.robot_ids([int(k)])[0])

    for key in ("crashed", "crashed_after_close", "crashes_not_reached"):
        out[key] = {cam(k): v for k, v in section.get(key, {}).items()}
    out["robots_lost"] = {cam(k): ids.robot_ids(v) for k, v in
                          section.get("robots_lost", {}).items()}
    out["injected"] = {**section["injected"], "crash": [
        f"{ids.robot_ids([int(c.split('@')[0])])[0]}@{c.split('@')[1]}"
        for c in section["injected"].get("crash", [])]}
    return out
