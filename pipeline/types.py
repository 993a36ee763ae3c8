"""Plain data records passed between the pipeline stages.

Conventions (docs/DESIGN.md): camera ``i`` is robot ``i`` (0-based); feature ``r`` of camera ``i`` is
``(i, r)``; poses are ``cam_from_world`` (``x_cam = R @ x_world + t``); pixel coordinates follow
OpenCV (origin at the centre of the top-left pixel).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pipeline.errors import InputError
from pipeline.validate import is_number

__all__ = ["View", "Features", "PairMatches", "Links", "LinkLedger", "RunRecord", "id_array"]


@dataclass
class View:
    """One camera's image and calibration.

    Attributes
    ----------
    name : str
        Image name (file name for real images, ``cam00`` … for rendered ones).
    image : ndarray, (H, W, 3) uint8 RGB or (H, W) uint8 gray
    K : ndarray, (3, 3) float64
        Pinhole intrinsics.
    R, t : ndarray, (3, 3) and (3,) float64
        ``cam_from_world`` pose; ``None`` for real images whose pose is unknown.
    depth : ndarray, (H, W) float32 or None
        Synthetic only: z-depth in the camera frame, ``inf`` where no surface was hit.
    intrinsics_known : bool
        ``False`` when K is a guess (matching then uses the fundamental matrix).
    intrinsics_source : str
        Where K came from for real images (``K.txt``, ``exif-35mm``, ``exif-focal-plane``,
        ``guess``); empty for rendered views.
    """

    name: str
    image: np.ndarray
    K: np.ndarray
    R: np.ndarray | None = None
    t: np.ndarray | None = None
    depth: np.ndarray | None = None
    intrinsics_known: bool = True
    intrinsics_source: str = ""

    @property
    def size(self) -> tuple[int, int]:
        """``(width, height)`` in pixels."""
        return int(self.image.shape[1]), int(self.image.shape[0])


@dataclass
class Features:
    """Local features of one camera.

    Attributes
    ----------
    keypoints : ndarray, (N, 2) float32, OpenCV pixel convention
    descriptors : ndarray, (N, D) float32 (SIFT) or uint8 (binary descriptors)
    scales : ndarray, (N,) float32 — keypoint size in pixels
    method : str — ``sift``, ``orb``, ``akaze`` or ``surf``
    """

    keypoints: np.ndarray
    descriptors: np.ndarray
    scales: np.ndarray
    method: str

    def __len__(self) -> int:
        return int(self.keypoints.shape[0])


@dataclass
class PairMatches:
    """The one-to-one association ``A_ij`` of one communication edge ``(i, j)``, ``i < j``.

    Attributes
    ----------
    i, j : int — cameras, ``i < j``
    pairs : ndarray, (M, 2) int32 — rows ``(r, s)``: feature ``r`` of ``i`` ↔ feature ``s`` of ``j``
    ratio : ndarray, (M,) float32 — Lowe ratio of the match (lower is better)
    epipolar_error : ndarray, (M,) float32 — Sampson error in pixels
    n_putative : int — matches after the ratio/mutual test, before RANSAC
    reason : str — empty when the association is usable, else why it is empty
    """

    i: int
    j: int
    pairs: np.ndarray
    ratio: np.ndarray
    epipolar_error: np.ndarray
    n_putative: int = 0
    reason: str = ""


def id_array(values, what: str) -> np.ndarray:
    """``values`` as a 1-D int64 array of ids; ValueError naming the first value that is not
    a whole number an int64 holds (``1.0`` is one, ``1.5``, ``nan``, ``1e30`` and ``2**63`` are
    not: a cast truncated, wrapped or overflowed them silently; nor are booleans, strings or
    ``None``: a mask or text given for ids would be read as ids 0 and 1 or parsed)."""
    try:
        v = np.asarray(values)
    except ValueError:  # a ragged nesting
        raise ValueError(f"{what} must be a flat sequence of whole-number ids") from None
    if v.ndim > 1:  # (n, 1) or (2, n) given for a list: flattening would invent entries' order
        raise ValueError(f"{what} must be a flat sequence of whole-number ids, not an array of "
                         f"shape {v.shape}")
    if v.dtype.kind == "O":  # Python ints past int64, None, mixed objects
        flat = v.reshape(-1)
        for k, x in enumerate(flat.tolist()):
            if not is_number(x) \
                    or not float(x).is_integer() or not -2**63 <= x < 2**63:
                raise ValueError(f"{what}[{k}] = {flat[k]!r} is not a whole-number id")
        v = np.asarray(flat.tolist(), dtype=np.float64 if any(
            isinstance(x, (float, np.floating)) for x in flat.tolist()) else np.int64)
    if v.size == 0:
        return np.zeros(0, dtype=np.int64)
    if v.dtype.kind not in "iuf":  # bool masks, strings, complex: no id is meant
        flat = v.reshape(-1)
        raise ValueError(f"{what}[0] = {flat[0].item()!r} is not a whole-number id: give integers, got dtype "
                         f"{v.dtype}")
    if v.dtype.kind == "f":
        bad = ~np.isfinite(v) | (v != np.round(v)) | (np.abs(v) >= 2.0**63)
    elif v.dtype.kind == "u":
        bad = v > np.iinfo(np.int64).max
    else:
        return np.asarray(v, dtype=np.int64).reshape(-1)
    if bad.any():
        k = int(np.flatnonzero(bad.reshape(-1))[0])
        raise ValueError(f"{what}[{k}] = {v.reshape(-1)[k].item()!r} is not a whole-number id")
    return v.astype(np.int64).reshape(-1)


@dataclass
class Links:
    """All links of the association graph, each undirected link stored once with ``cam_i < cam_j``.

    Attributes
    ----------
    cam_i, feat_i, cam_j, feat_j : ndarray, (L,) int64
    quality : ndarray, (L,) float64 — higher is better (used by the centralized quality merge)
    """

    cam_i: np.ndarray
    feat_i: np.ndarray
    cam_j: np.ndarray
    feat_j: np.ndarray
    quality: np.ndarray = field(default=None)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        for name in ("cam_i", "feat_i", "cam_j", "feat_j"):
            try:
                setattr(self, name, id_array(getattr(self, name), f"Links: {name}"))
            except ValueError as exc:
                raise InputError(str(exc)) from None
        n = self.cam_i.shape[0]
        lengths = {k: getattr(self, k).shape[0] for k in ("cam_i", "feat_i", "cam_j", "feat_j")}
        if len(set(lengths.values())) > 1:
            raise InputError("Links: cam_i, feat_i, cam_j, feat_j must have the same length, got "
                             + ", ".join(f"{k} {v}" for k, v in lengths.items())
                             + ": give one entry per link in each")
        if self.quality is None:
            self.quality = np.ones(n, dtype=np.float64)
        try:
            q = np.asarray(self.quality, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise InputError(f"Links: quality must be numbers, one per link ({exc})") from None
        if q.ndim > 1:  # a (2, n) or (n, 2) table flattened would pair values with other links
            raise InputError(f"Links: quality must be a flat sequence of one number per link, "
                             f"not an array of shape {q.shape}")
        self.quality = q.reshape(-1)
        if self.quality.shape[0] != n:
            raise InputError(f"Links: quality has length {self.quality.shape[0]}, expected {n} "
                             "(one per link)")

    def __len__(self) -> int:
        return int(self.cam_i.shape[0])

    def subset(self, mask: np.ndarray) -> Links:
        """The links where ``mask`` is true (boolean mask or index array).

        Raises
        ------
        InputError
            A boolean mask of another length than the links, an index outside ``0..L-1``,
            or an index given twice (a link is stored once: a mask of 0 / 1 integers, read as
            indices, repeated links 0 and 1), or neither booleans nor integers.

        Examples
        --------
        >>> links = Links([0, 0, 1], [0, 1, 0], [1, 1, 2], [0, 1, 0])
        >>> links.subset([True, False, True]).feat_i.tolist(), links.subset([2, 0]).cam_i.tolist()
        ([0, 0], [1, 0])
        """
        sel = self._selection(mask)
        return Links(self.cam_i[sel], self.feat_i[sel], self.cam_j[sel], self.feat_j[sel],
                     self.quality[sel])

    def _selection(self, mask) -> np.ndarray:
        """``mask`` of :meth:`subset` as a boolean ``(L,)`` mask or a 1-D index array,
        checked."""
        n = len(self)
        m = np.asarray(mask)
        if m.size == 0 and m.ndim == 1 and m.dtype.kind in "biuf":  # [] is float64
            return np.zeros(0, dtype=np.int64)
        if m.dtype == bool:
            if m.shape != (n,):
                raise InputError(f"Links.subset: a mask of shape {m.shape} for {n} links; give "
                                 f"one boolean per link ({n},), or link indices")
            return m
        if m.dtype.kind not in "iu" or m.ndim != 1:
            raise InputError(f"Links.subset: give a boolean mask ({n},) or a flat array of "
                             f"link indices, not an array of dtype {m.dtype} and shape {m.shape}")
        out = np.flatnonzero((m < 0) | (m >= n))
        if out.size:
            raise InputError(f"Links.subset: index {m[out[0]].item()} is outside 0..{n - 1} "
                             f"({n} links)")
        if np.unique(m).size != m.size:
            raise InputError("Links.subset: an index is given more than once (a link is stored "
                             "once); for a mask of 0 / 1 give booleans (mask.astype(bool))")
        return m

    @staticmethod
    def from_matches(matches: list[PairMatches]) -> Links:
        """Concatenate per-edge associations; quality is ``1 - ratio``."""
        parts = [m for m in matches if len(m.pairs)]
        if not parts:
            z = np.zeros(0, dtype=np.int64)
            return Links(z, z, z, z, np.zeros(0))
        return Links(
            np.concatenate([np.full(len(m.pairs), m.i) for m in parts]),
            np.concatenate([m.pairs[:, 0] for m in parts]),
            np.concatenate([np.full(len(m.pairs), m.j) for m in parts]),
            np.concatenate([m.pairs[:, 1] for m in parts]),
            np.concatenate([1.0 - m.ratio.astype(np.float64) for m in parts]),
        )


LINK_STATUSES = ("kept", "deleted")


@dataclass
class LinkLedger:
    """What the stages decided for every link matching produced: the one per-link record.

    Every stage that cuts links writes here (:meth:`cut`), the ``links.csv`` writer and the
    Rerun log read it. A link is never removed from the ledger; a cut link keeps the stage that
    cut it and when (docs/DESIGN.md "Run outputs").

    Attributes
    ----------
    links : Links, (L,) — every link produced by matching (or read from the user's file)
    status : ndarray, (L,) object str — ``kept`` or ``deleted``
    reason : ndarray, (L,) object str — stage that cut the link (``resolution``,
        ``robot-lost``, ``fusion-outlier``, …), ``''`` if kept
    round : ndarray, (L,) int64 — round of that stage in which it was cut, ``-1`` if kept
    iteration : ndarray, (L,) int64 — detection/resolution iteration that cut it, ``-1``
        otherwise
    case : ndarray, (L,) object str — Alg. 1 case (``b`` or ``c``) of a link cut by
        resolution, ``''`` otherwise
    truth : ndarray, (L,) int8 or None — ``1`` good, ``0`` spurious, ``-1`` unknown; ``None``
        when no link's truth is known (real images, the user's links)
    conflictive_before : ndarray, (L,) bool — the link lies in a conflictive set before
        resolution (Aragüés et al., Def. 2.4)

    Examples
    --------
    >>> ledger = LinkLedger.all_kept(Links([0, 0], [1, 2], [1, 1], [1, 2]))
    >>> ledger.cut(np.array([False, True]), "resolution", 3)
    >>> ledger.status.tolist(), ledger.reason.tolist(), ledger.round.tolist()
    (['kept', 'deleted'], ['', 'resolution'], [-1, 3])
    """

    links: Links
    status: np.ndarray
    reason: np.ndarray
    round: np.ndarray
    iteration: np.ndarray
    case: np.ndarray
    truth: np.ndarray | None = None
    conflictive_before: np.ndarray | None = None

    def __post_init__(self) -> None:
        L = len(self.links)
        self.status = np.asarray(self.status).astype(str).astype(object).reshape(-1)
        self.reason = np.asarray(self.reason).astype(str).astype(object).reshape(-1)
        self.round = np.asarray(self.round, dtype=np.int64).reshape(-1)
        self.iteration = np.asarray(self.iteration, dtype=np.int64).reshape(-1)
        self.case = np.asarray(self.case).astype(str).astype(object).reshape(-1)
        if self.truth is not None:
            self.truth = np.asarray(self.truth, dtype=np.int8).reshape(-1)
        if self.conflictive_before is None:
            self.conflictive_before = np.zeros(L, dtype=bool)
        self.conflictive_before = np.asarray(self.conflictive_before, dtype=bool).reshape(-1)
        self.check()

    def check(self) -> None:
        """InputError (a ValueError) unless every per-link array has one entry per link and
        every status is ``kept`` or ``deleted``, naming the field."""
        L = len(self.links)
        for name in ("status", "reason", "round", "iteration", "case", "truth",
                     "conflictive_before"):
            arr = getattr(self, name)
            if arr is not None and np.asarray(arr).reshape(-1).shape[0] != L:
                raise InputError(f"LinkLedger.{name} has length {np.asarray(arr).shape[0]}, "
                                 f"expected one per link ({L}): give one entry per link")
        bad = ~np.isin(np.asarray(self.status).astype(str), LINK_STATUSES)
        if bad.any():
            raise InputError(f"LinkLedger.status must be 'kept' or 'deleted', got "
                             f"{np.asarray(self.status)[bad][0]!r}")

    @staticmethod
    def all_kept(links: Links, truth: np.ndarray | None = None,
                 conflictive_before: np.ndarray | None = None) -> LinkLedger:
        """Every link kept, nothing cut yet."""
        L = len(links)
        return LinkLedger(links, np.full(L, "kept", dtype=object), np.full(L, "", dtype=object),
                          np.full(L, -1, dtype=np.int64), np.full(L, -1, dtype=np.int64),
                          np.full(L, "", dtype=object), truth, conflictive_before)

    def __len__(self) -> int:
        return len(self.links)

    @property
    def kept(self) -> np.ndarray:
        """``(L,)`` bool: the link survived every stage."""
        return self.status == "kept"

    @property
    def good(self) -> np.ndarray | None:
        """``(L,)`` bool: the link is good (synthetic ground truth), or ``None`` if unknown."""
        return None if self.truth is None else self.truth == 1

    def cut(self, mask: np.ndarray, reason: str, round: int | np.ndarray, *,
            iteration: int | np.ndarray | None = None,
            case: str | np.ndarray | None = None) -> None:
        """Mark the links selected by ``mask`` (bool ``(L,)`` or indices) deleted by ``reason``
        in ``round`` (a number or one per selected link); ``iteration`` and ``case`` are kept
        unless given. ``mask`` is checked as :meth:`Links.subset` checks it (a 0 / 1 integer
        mask cut links 0 and 1)."""
        mask = self.links._selection(mask)
        self.status[mask] = "deleted"
        self.reason[mask] = reason
        self.round[mask] = round
        if iteration is not None:
            self.iteration[mask] = iteration
        if case is not None:
            self.case[mask] = case

    def place(self, rows: np.ndarray, sub: LinkLedger) -> None:
        """Write the decisions of ``sub``, a ledger of the links ``rows`` (indices) of this one
        (e.g. the consistency stage run on the links no earlier check cut), into these rows:
        ``status``, ``reason``, ``round``, ``iteration``, ``case`` and ``conflictive_before``.

        >>> ledger = LinkLedger.all_kept(Links([0, 0, 1], [0, 1, 0], [1, 1, 2], [0, 1, 0]))
        >>> sub = LinkLedger.all_kept(ledger.links.subset(np.array([False, True, True])))
        >>> sub.cut(np.array([True, False]), "resolution", 2)
        >>> ledger.place(np.array([1, 2]), sub)
        >>> ledger.status.tolist(), ledger.round.tolist()
        (['kept', 'deleted', 'kept'], [-1, 2, -1])
        """
        for name in ("status", "reason", "round", "iteration", "case", "conflictive_before"):
            getattr(self, name)[rows] = getattr(sub, name)


@dataclass
class RunRecord:
    """Everything a run produced, handed to ``viz`` (which only reads it).

    Attributes
    ----------
    views : list[View]
    features : list[Features]
    ledger : LinkLedger — every link produced by matching and what the stages did to it
    points : ndarray, (P, 3) — triangulated track points after cleaning (world frame)
    point_tracks : ndarray, (P,) int — track id of each point
    gt_points : ndarray, (G, 3) or None — ground-truth points of the kept tracks (synthetic)
    fused_points : ndarray, (F, 3) or None — landmark estimates fused by dynamic voting
    report_markdown : str — the report table, for a text panel
    """

    views: list
    features: list
    ledger: LinkLedger
    points: np.ndarray
    point_tracks: np.ndarray
    gt_points: np.ndarray | None = None
    fused_points: np.ndarray | None = None
    report_markdown: str = ""
    #: (P, 3) uint8 RGB of ``points`` taken from the images, or None (drawn white)
    point_colors: np.ndarray | None = None
