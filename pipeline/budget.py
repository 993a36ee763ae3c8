"""The one memory guard: what a job will allocate, counted before it allocates it.

A command that reads a user's files (``resolve``, ``clean-db``, ``clean-h5``) holds one
:class:`MemoryBudget` with the ``--max-memory-gb`` limit (:func:`limit_gb`: a finite number
of GB above 0). Before each allocation that grows with the input it adds that allocation's
estimate, from what the input declares (rows of a file, sizes a database or an HDF5 file
declares, cameras, links, association sets), and the first estimate that takes the total
above the limit is an InputError naming that part, the total and what to do; nothing of
that size has been allocated then. The parts, each measured on inputs made to grow only
it (peak resident memory of ``resolve`` / ``clean-db`` / ``clean-h5`` beyond the ~75 MB of
the interpreter and libraries, rounded up):

- :data:`BYTES_PER_ROW`: a row of a links or comm-graph file, parsed, checked and held as a
  link with its ledger (300,000 links between 8 cameras: 1.3 KB a link, the detection's own
  share below included).
- :data:`BYTES_PER_CAMERA`: a robot of the simulated team, its state, blocks and network
  queues (30,000 cameras in 10,000 separate triangles: 9.3 KB a camera).
- :data:`BYTES_PER_EDGE`: a communication edge (20,000 cameras, 200,000 edges: 0.4 KB an
  edge).
- :data:`BYTES_PER_ENTRY` and :data:`BYTES_PER_ROW_CROSSING`: the distributed detection. In
  the detection of Aragüés et al. (Sec. III, eq. 5) every robot ``i`` propagates the rows
  ``X_ij(t)`` of the powers of the association matrix: after ``d`` rounds robot ``i`` holds,
  for each of its features, every feature of that feature's association set. Summed over the
  robots this is ``sum_s |s|^2`` entries over the association sets ``s`` (Def. 2.4), whatever
  the ids — a few noisy links among 10 cameras that chain 10,000 features into one set need
  10^8 entries. Measured on such inputs (11,250 and 22,500 random links among 10 cameras,
  sets of 8,844 and 9,975 features): about 36 bytes of peak memory per entry (the robots'
  sparse blocks, the copies in flight and the per-round work arrays). A row also travels to
  every robot its feature is linked to (a robot sends the rows its neighbour reads), so on a
  dense graph, where a set is joined in a round or two, every row crosses each of its
  feature's links at once: ``sum_s |s| · 2 L_s`` entries in flight (``L_s`` the links of set
  ``s``), :data:`BYTES_PER_ROW_CROSSING` each; the estimate is the larger of the two terms
  (the entries alone where the simulator's batched engine runs it: it holds a round's
  result, not the rows in flight; 101 frames below: 0.46 GB peak RSS after the change that
  made it so, against 36 bytes an entry's 0.25 GB and the 0.2 GB counted before it).
  Measured through ``resolve --resolution paper`` on the CMU hotel's descriptor matches
  (complete graphs; peak RSS beyond the interpreter and the rows): 60 frames (518,400
  entries, about 59 links a feature) 0.2 GB, 80 frames (4.03 M, 79) 2.5 GB, 101 frames
  (6.94 M, 100) 7.5 GB, where 36 bytes an entry alone gave 0.25 GB; the crossings at 12
  bytes give 0.37, 3.8 and 8.3 GB.
- :data:`BYTES_PER_LIST_ENTRY`: the evidence rule's detection (bounded label flooding,
  :mod:`pipeline.consistency.setlists`): every feature of a set ``s`` holds up to ``B + 1``
  ids of it (``B`` the bundle budget), ``sum_s |s| · min(|s|, B + 1)`` entries. Measured on
  random links among 10 cameras (``B = 978``; 45,000 and 90,000 links, sets of 19,956 and
  39,919 features, 1.95e7 and 3.91e7 entries: peak 1.27 and 2.33 GB): 54 bytes per entry
  (the lists, the entries that entered in a round, the merge's pieces).
- :data:`BYTES_PER_LANDMARK_PAIR`: ``run-landmarks``' matching of one image pair (the
  descriptor costs of every landmark pair, the epipolar band, the Hungarian method's copy),
  for the comm graph's largest pair ``K_i · K_j``. Measured (peak RSS beyond a 4-frame run's
  165 MB, ``--no-baselines``): two images of 5,000 landmarks 580 MB (23 bytes per pair), of
  2,000 landmarks 53 MB (13).
- data read from a database or an HDF5 file: its declared bytes times the copies made of
  them (:data:`COPIES_OF_READ_DATA`), counted from the declared sizes before any is read.
- :func:`baselines_bytes`: the centralized baselines of ``--baselines`` (a copy of the links
  per baseline, and the dense eigenproblem of a spectral baseline's largest component,
  at most :data:`BASELINE_DENSE_FEATURES` features, with LAPACK's workspace).
- :data:`BYTES_PER_ROBOT_PIXEL`: a rendered formation, per robot and pixel of its image
  (rendering, features, matching, cleaning and the report; ring formations of 10 and 30
  robots: 87 bytes at 640x480, 78 at 320x240).
- :func:`check_motion_memory`: an online run (``run-formation --steps N``) renders every
  frame first and holds them to its end, :data:`BYTES_PER_FRAME_PIXEL` per frame pixel, plus
  one step's matching and cleaning at :data:`BYTES_PER_ROBOT_PIXEL`.
- :func:`fusion_bytes`: the simulator's fusion stage, counted once the consistency stage has
  named the tracks (:func:`check_fusion_memory`). It holds per-(track, robot) tables over the
  whole team (keypoints, local estimates, covariances, draws, votes) and per track its
  observers' flood and decisions: :data:`BYTES_PER_FUSION_TRACK_ROBOT` per track and team
  robot plus :data:`BYTES_PER_FUSION_OBSERVER_PAIR` per (track, observer, observer). Measured
  (tracemalloc peak of the stage, run-formation): 200 robots on ring2 at 320x240 (2,912
  tracks, sum k^2 = 124,173) 481 MB; 60 on complete at 160x120 (689, 31,620) 58 MB; 400 on
  ring at 160x120, --max-features 100 (834, 16,392) 161 MB. The two constants give 597, 88
  and 233 MB there.
"""

from __future__ import annotations

import os

import numpy as np

from pipeline.errors import InputError
from pipeline.progress import counted
from pipeline.types import Links

__all__ = ["BASELINE_DENSE_FEATURES", "baselines_bytes", "spectral_dense_features", "BYTES_PER_CAMERA", "BYTES_PER_LANDMARK_PAIR", "BYTES_PER_EDGE", "BYTES_PER_ENTRY", "BYTES_PER_ROW_CROSSING", "BYTES_PER_FRAME_PIXEL", "check_motion_memory", "BYTES_PER_LIST_ENTRY",
           "BYTES_PER_ROBOT_PIXEL", "BYTES_PER_FUSION_OBSERVER_PAIR", "BYTES_PER_FUSION_TRACK_ROBOT",
           "check_fusion_memory", "fusion_bytes",
           "BYTES_PER_ROW",
           "COPIES_OF_READ_DATA", "DEFAULT_LIMIT_GB", "MAX_LIMIT_GB", "MemoryBudget",
           "check_detection_memory", "check_formation_memory", "BYTES_PER_SYNC_LINK",
           "SYNC_CAMERA_SETS_PER_FEATURE", "camera_sets_bytes", "count_lines", "detection_entries", "limit_gb",
           "row_crossings"]

#: measured peak bytes per entry of ``sum_s |s|^2`` (2.7 GB for 7.8e7 entries)
BYTES_PER_ENTRY = 36
#: bytes per entry of a row crossing one link of its feature in the detection (module notes)
BYTES_PER_ROW_CROSSING = 12
#: measured peak bytes per entry of the evidence rule's set lists (54, module notes)
BYTES_PER_LIST_ENTRY = 64
#: peak bytes per landmark pair of ``run-landmarks``' matching of one image pair (module notes)
BYTES_PER_LANDMARK_PAIR = 24
#: bytes per row of a links or comm-graph file (measured 1.3 KB per link)
BYTES_PER_ROW = 1500
#: peak bytes per link of the ``sync`` rule's robots beyond the rows of the links file
#: (:data:`BYTES_PER_ROW`, counted apart). Measured through ``resolve`` (peak RSS beyond the
#: interpreter's ~75 MB, per link): CMU hotel, 101 frames, descriptor links (151,500 links)
#: 1.80 KB with ``sync``, 1.85 KB with ``evidence``, 0.75 KB with ``paper-labels`` (its robots
#: hold four numbers per feature: about what reading and holding the rows costs); the ring2
#: team of 3,000 cameras (180,000 links) 1.46 / 1.55 / 0.88 KB, of 10,000 cameras 1.45 KB with
#: ``sync``. So at most about 1.1 KB beyond the rows; 1.2 KB with the rows' own 1.5 KB leaves
#: the sum 50 % above the largest measured (it was 2.2 KB, measured in a process that held the
#: links without their file, and so counted the rows twice)
BYTES_PER_SYNC_LINK = 1_200
#: camera bit sets (``8 + 8 * ceil(n/64)`` bytes each, ``n`` the cameras) the ``sync`` rule
#: holds per linked feature: a robot holds the set of each of its own clusters, the team's
#: merge keeps a growing buffer of every cluster's. Measured through ``resolve`` on chains
#: of cameras (``n`` of 40,000 and 50,000; peak RSS beyond ``paper-labels`` on the same
#: links): pairs of features 1.56 sets per linked feature (1.25 GB for 160,000 features),
#: tracks of three 0.87 (0.53 GB for 120,000). Over thousands of cameras these sets, not the
#: links, make the peak: they grow with features times cameras
SYNC_CAMERA_SETS_PER_FEATURE = 2
#: bytes per camera (robot) of the simulated team (measured 9.3 KB)
BYTES_PER_CAMERA = 12_000
#: bytes per communication edge (measured 0.4 KB)
BYTES_PER_EDGE = 600
#: bytes per robot and pixel of a rendered formation (measured 78-87)
BYTES_PER_ROBOT_PIXEL = 90
#: bytes per pixel of every frame an online run renders, held for the whole run (its uint8
#: image and float32 depth, 7; the process grew by 14.1 per frame pixel rendering formation d
#: at 320x240 for 20 steps, :func:`data_synth.motion.render_motion`, ``ru_maxrss``)
BYTES_PER_FRAME_PIXEL = 16
#: the fusion stage's bytes per (track, team robot) (module notes)
BYTES_PER_FUSION_TRACK_ROBOT = 600
#: the fusion stage's bytes per (track, observer, observer) (module notes)
BYTES_PER_FUSION_OBSERVER_PAIR = 2000
#: the largest component a spectral baseline solves densely
#: (:data:`pipeline.consistency.spectral.DENSE_VALUES_MAX`)
BASELINE_DENSE_FEATURES = 4000
#: float64 matrices of that size held at once by the dense eigensolver (matrix, eigenvectors,
#: workspace)
BASELINE_DENSE_COPIES = 3
#: copies made of data read from a file (the library's array, ours, a converted one)
COPIES_OF_READ_DATA = 3
#: default limit of the estimate, in GB (10^9 bytes)
DEFAULT_LIMIT_GB = 2.0
#: largest limit accepted (a number beyond any machine turns the guard off in effect)
MAX_LIMIT_GB = 1e6


def limit_gb(value, flag: str = "--max-memory-gb") -> float:
    """``value`` as a limit in GB: a finite number above 0 (``nan`` would turn every
    comparison false, and so the guard off)."""
    from pipeline.validate import positive_number

    return positive_number(value, flag, "GB", MAX_LIMIT_GB, "the memory limit in GB", "4")


class MemoryBudget:
    """The memory one job will allocate, counted part by part (module notes).

    Example
    -------
    >>> b = MemoryBudget(1.0)
    >>> b.add("rows of the links file", 2_000 * BYTES_PER_ROW)
    >>> b.add("robots (30,000 cameras)", 30_000 * BYTES_PER_CAMERA)
    >>> round(b.total / 1e9, 2)
    0.36
    """

    def __init__(self, limit: float = DEFAULT_LIMIT_GB, flag: str = "--max-memory-gb"):
        self.limit = limit_gb(limit, flag)
        self.flag = flag
        self.parts: dict[str, float] = {}

    @property
    def total(self) -> float:
        return float(sum(self.parts.values()))

    def add(self, what: str, nbytes: float, advice: str = "") -> None:
        """Count ``nbytes`` for ``what``; InputError if the total then exceeds the limit
        (``advice``: what the user can change in the input, said first)."""
        self.parts[what] = self.parts.get(what, 0.0) + float(nbytes)
        if self.total > self.limit * 1e9:
            others = self.total - self.parts[what]
            also = f" (with {_size(others)} counted before it)" if others else ""
            raise InputError(
                f"{what} would need about {_size(self.parts[what])} of memory{also}, above "
                f"the limit of {self.limit:g} GB; {advice + ', or ' if advice else ''}raise the "
                f"limit with {self.flag}")

    # The parts in the units a reader knows: a module below this layer (an input reader)
    # is handed the budget and counts through these, without importing this module.

    def add_read(self, what: str, declared_bytes: float, advice: str = "") -> None:
        """Count data a file declares, before it is read: its bytes times
        :data:`COPIES_OF_READ_DATA`."""
        self.add(what, declared_bytes * COPIES_OF_READ_DATA, advice)

    def add_cameras(self, what: str, n: int, advice: str = "") -> None:
        """Count ``n`` robots of the simulated team (:data:`BYTES_PER_CAMERA` each)."""
        self.add(what, n * BYTES_PER_CAMERA, advice)

    def add_rows(self, what: str, n: int, advice: str = "") -> None:
        """Count ``n`` links held with their ledger (:data:`BYTES_PER_ROW` each)."""
        self.add(what, n * BYTES_PER_ROW, advice)


def _size(nbytes: float) -> str:
    return f"{nbytes / 1e9:.1f} GB" if nbytes >= 1e8 else f"{nbytes / 1e6:.2g} MB"


def count_lines(path: str | os.PathLike) -> int:
    """Lines of a text file (``\\n`` count, plus a last line without one), read in blocks:
    an upper bound on its rows, known before any is parsed."""
    n, last = 0, b"\n"
    with open(path, "rb") as f:
        while block := f.read(1 << 20):
            n += block.count(b"\n")
            last = block[-1:]
    return n + (last != b"\n")


def detection_entries(features_per_camera, links: Links,
                      keep: int | None = None) -> tuple[int, int]:
    """``(sum_s |s|^2, largest |s|)`` over the association sets of ``links``; with ``keep``,
    ``sum_s |s| · min(|s|, keep)`` (every feature holds at most ``keep`` ids of its set)."""
    s, _ = _set_sizes(features_per_camera, links)
    held = s if keep is None else np.minimum(s, int(keep))
    return int((s * held).sum()), int(s.max(initial=0))


def row_crossings(features_per_camera, links: Links) -> int:
    """``sum_s |s| · 2 L_s`` over the association sets of ``links`` (``L_s`` its links): the
    entries of the detection's rows when each row crosses every link of its feature once
    (module notes)."""
    _, per_link = _set_sizes(features_per_camera, links, of_links=True)
    return int(2 * per_link.sum())


def _set_sizes(features_per_camera, links: Links, of_links: bool = False):
    """Sizes of the association sets of two features or more; with ``of_links``, also the
    size of each link's set (one entry per link)."""
    from pipeline.association import AssociationGraph, conflictive_labels

    graph = AssociationGraph(features_per_camera, links)
    labels, sizes, _ = conflictive_labels(graph)
    s = sizes[sizes >= 2].astype(np.int64)
    if not of_links:
        return s, None
    a, _ = graph.global_ids()
    return s, sizes[labels[a]] if len(links) else np.zeros(0, np.int64)


def camera_sets_bytes(features_per_camera, links: Links) -> tuple[int, int]:
    """``(bytes, linked features)`` of the ``sync`` rule's camera bit sets on ``links``
    (:data:`SYNC_CAMERA_SETS_PER_FEATURE`)."""
    fpc = np.asarray(features_per_camera, dtype=np.int64).reshape(-1)
    if not len(links):
        return 0, 0
    offsets = np.concatenate([[0], np.cumsum(fpc)])
    ends = np.concatenate([offsets[np.asarray(links.cam_i, dtype=np.int64)] + links.feat_i,
                           offsets[np.asarray(links.cam_j, dtype=np.int64)] + links.feat_j])
    linked = int(np.unique(ends).size)
    per_set = 8 + 8 * ((fpc.size + 63) // 64)
    return linked * SYNC_CAMERA_SETS_PER_FEATURE * per_set, linked


def check_detection_memory(features_per_camera, links: Links, budget: MemoryBudget | float,
                           flag: str = "--max-memory-gb", *, detection: bool = True,
                           set_lists: int | None = None, camera_sets: bool = False,
                           in_flight: bool = True) -> None:
    """Count the consistency stage's memory in ``budget`` (or a limit in GB): InputError if it
    takes the total above the limit (module notes).

    ``detection``: the rule runs the paper's detection (Sec. III), whose rows hold every
    feature of a set (``Σ |C|²``); ``False`` for a rule without it (``sync``, whose robots
    hold their links and the far ends' clusters; ``paper-labels``, four numbers per feature
    besides its links): :data:`BYTES_PER_SYNC_LINK` per link, the larger of the two.
    ``set_lists``: the bundle budget ``B`` of a rule whose own detection floods up to
    ``B + 1`` ids of each set (``evidence``): :data:`BYTES_PER_LIST_ENTRY` per entry too.
    ``camera_sets``: the rule holds a bit set of every camera per cluster (``sync``): the
    larger of that (:func:`camera_sets_bytes`) and the per-link figure, which was measured
    where the sets were a small part of it. ``in_flight``: the rows crossing the links are
    held at once (robots stepped one by one, or processes on one machine); ``False`` where
    the simulator's batched engine runs the detection (a lossless network, no fault: its
    product of eq. 5 holds the round's result, not the rows in flight), so only the entries
    count."""
    if not isinstance(budget, MemoryBudget):
        budget = MemoryBudget(budget, flag)
    if not detection:
        sets, linked = camera_sets_bytes(features_per_camera, links) if camera_sets else (0, 0)
        if sets > len(links) * BYTES_PER_SYNC_LINK:
            n = len(np.asarray(features_per_camera).reshape(-1))
            budget.add(f"the robots' clusters and their sets of cameras ({linked} features "
                       f"linked, a set of {n} cameras each)", sets,
                       "split the input (fewer cameras in one run)")
        else:
            budget.add(f"the robots' links and the clusters at their far ends ({len(links)} "
                       "links)", len(links) * BYTES_PER_SYNC_LINK,
                       "split the input")
        if set_lists is not None:
            entries, largest = detection_entries(features_per_camera, links, int(set_lists) + 1)
            budget.add(f"the evidence rule's detection (the links chain up to {largest} features "
                       f"into one association set; each feature holds up to {int(set_lists) + 1}"
                       " of its ids)", entries * BYTES_PER_LIST_ENTRY,
                       "such sets come from wrong links: clean them first, or use --resolution "
                       "sync (its memory follows the links)")
        return
    entries, largest = detection_entries(features_per_camera, links)
    crossings = row_crossings(features_per_camera, links)
    budget.add(f"the distributed detection (the links chain up to {largest} features into "
               "one association set; every robot holds every feature of its sets, eq. 5, and "
               "sends each row over every link of its feature)",
               max(entries * BYTES_PER_ENTRY,
                   crossings * BYTES_PER_ROW_CROSSING if in_flight else 0),
               "such sets come from wrong links: clean them first, or use --resolution sync "
               "(no detection) or paper-labels (Alg. 1 after a label-flooding detection): "
               "their memory follows the links")


def baselines_bytes(features_per_camera, links: Links) -> int:
    """Estimated peak of the centralized baselines on ``links`` (module notes): a copy of
    the links per baseline and the spectral baselines' largest eigenproblem
    (:func:`spectral_dense_features`)."""
    dense = spectral_dense_features(features_per_camera, links)
    return int(len(links)) * BYTES_PER_ROW + BASELINE_DENSE_COPIES * dense * dense * 8


def spectral_dense_features(features_per_camera, links: Links) -> int:
    """Size of the largest matrix the spectral baselines solve densely, at least.

    A component of ``m_c`` features gets ``k_c`` universe points, at least the most features
    of one camera in it (:func:`pipeline.consistency.spectral.universe_size_count`); its
    leading ``k_c`` eigenpairs are solved densely when ``4 k_c >= m_c``
    (:func:`pipeline.consistency.spectral._top_eigen`), whatever ``m_c``: three cameras whose
    links chain 33,675 features into one set (``k_c`` over 11,000) ran out of memory past
    5 GB where :data:`BASELINE_DENSE_FEATURES` alone counted 0.4 GB. Otherwise the largest
    component of at most :data:`BASELINE_DENSE_FEATURES` features, as before."""
    fpc = np.asarray(features_per_camera, dtype=np.int64).reshape(-1)
    m_total = int(fpc.sum())
    dense = min(m_total, BASELINE_DENSE_FEATURES)
    if not len(links):
        return dense
    from pipeline.association import AssociationGraph

    graph = AssociationGraph(fpc, links)
    a, b = graph.global_ids()
    linked = np.zeros(m_total, dtype=bool)
    linked[a] = linked[b] = True
    comp = graph.components()
    cam = np.repeat(np.arange(fpc.size, dtype=np.int64), fpc)
    g = np.flatnonzero(linked)
    size = np.bincount(comp[g])
    big = np.flatnonzero(size > BASELINE_DENSE_FEATURES)
    if big.size == 0:
        return dense
    sel = g[np.isin(comp[g], big)]
    keys, counts = np.unique(comp[sel] * np.int64(fpc.size) + cam[sel], return_counts=True)
    k_min = np.zeros(size.size, dtype=np.int64)
    np.maximum.at(k_min, keys // fpc.size, counts)
    must = big[4 * k_min[big] >= size[big]]
    return max(dense, int(size[must].max(initial=0)))


def check_formation_memory(n_robots: int, size: tuple[int, int], limit,
                           flag: str = "--max-memory-gb", *, robots_option: bool = True) -> None:
    """InputError, before anything is rendered, when a formation of ``n_robots`` robots at
    ``size`` would need more than ``limit`` GB (:data:`BYTES_PER_ROBOT_PIXEL`).
    ``robots_option``: the command takes ``--robots`` (``run-formations`` and
    ``match-formation`` render the paper's six), so the message may advise fewer."""
    w, h = size
    MemoryBudget(limit, flag).add(
        f"rendering and cleaning the views of {n_robots} robots at {w}x{h}",
        n_robots * w * h * BYTES_PER_ROBOT_PIXEL,
        "fewer --robots or a smaller --size" if robots_option else "a smaller --size")


def check_motion_memory(n_robots: int, steps: int, size: tuple[int, int], limit,
                        flag: str = "--max-memory-gb") -> None:
    """InputError, before anything is rendered, when an online run of ``steps`` steps would
    need more than ``limit`` GB: its frames are rendered first and held for the whole run
    (:data:`BYTES_PER_FRAME_PIXEL`), and each step's matching and cleaning works on one
    frame per robot (:data:`BYTES_PER_ROBOT_PIXEL`)."""
    w, h = size
    b = MemoryBudget(limit, flag)
    b.add(f"rendering {counted(steps, 'step')} of {n_robots} robots at {w}x{h} "
          f"({counted(steps * n_robots, 'frame')})",
          steps * n_robots * w * h * BYTES_PER_FRAME_PIXEL,
          "fewer --steps, fewer --robots or a smaller --size")
    b.add(f"matching and cleaning one step of {n_robots} robots at {w}x{h}",
          n_robots * w * h * BYTES_PER_ROBOT_PIXEL, "fewer --robots or a smaller --size")


def fusion_bytes(n_robots: int, observers) -> int:
    """Estimated peak of the simulator's fusion stage on tracks with ``observers[b]``
    observers each among ``n_robots`` robots (module notes)."""
    k = np.asarray(observers, dtype=np.int64).reshape(-1)
    return int(len(k) * int(n_robots) * BYTES_PER_FUSION_TRACK_ROBOT
               + int((k * k).sum()) * BYTES_PER_FUSION_OBSERVER_PAIR)


def check_fusion_memory(n_robots: int, track_labels, limit,
                        flag: str = "--max-memory-gb") -> None:
    """InputError, before the fusion stage allocates, when the tracks of ``track_labels``
    (each feature's track name, ``-1`` outside tracks) among ``n_robots`` robots would need
    more than ``limit`` GB (:func:`fusion_bytes`)."""
    lab = np.asarray(track_labels, dtype=np.int64).reshape(-1)
    _, k = np.unique(lab[lab >= 0], return_counts=True)
    MemoryBudget(limit, flag).add(
        f"the fusion stage ({len(k)} tracks among {int(n_robots)} robots, up to "
        f"{int(k.max(initial=0))} observers a track)", fusion_bytes(n_robots, k),
        "fewer --robots or --max-features, or --no-fusion")
