"""Memory the distributed detection will need, estimated before it starts.

In the detection of Aragüés et al. (Sec. III, eq. 5) every robot ``i`` propagates the rows
``X_ij(t)`` of the powers of the association matrix: after ``d`` rounds robot ``i`` holds,
for each of its features, every feature of that feature's association set. Summed over the
robots this is ``sum_s |s|^2`` entries over the association sets ``s`` (Def. 2.4), whatever
the ids — a few noisy links among 10 cameras that chain 10,000 features into one set need
10^8 entries. Measured on such inputs (``bench``-style runs of ``resolve``, 11,250 and 22,500
random links among 10 cameras, sets of 8,844 and 9,975 features): about
:data:`BYTES_PER_ENTRY` bytes of peak memory per entry (the robots' sparse blocks, the
copies in flight and the per-round work arrays).

:func:`check_detection_memory` turns an input whose estimate exceeds the limit into an
InputError before any allocation, naming the largest set and the estimate.
"""

from __future__ import annotations

import numpy as np

from pipeline.errors import InputError
from pipeline.types import Links

__all__ = ["BYTES_PER_ENTRY", "DEFAULT_LIMIT_GB", "detection_entries", "check_detection_memory"]

#: measured peak bytes per entry of ``sum_s |s|^2`` (2.7 GB for 7.8e7 entries)
BYTES_PER_ENTRY = 36
#: default limit of the estimate, in GB (10^9 bytes)
DEFAULT_LIMIT_GB = 2.0


def detection_entries(features_per_camera, links: Links) -> tuple[int, int]:
    """``(sum_s |s|^2, largest |s|)`` over the association sets of ``links``."""
    from pipeline.association import AssociationGraph, conflictive_labels

    _, sizes, _ = conflictive_labels(AssociationGraph(features_per_camera, links))
    s = sizes[sizes >= 2].astype(np.int64)
    return int((s * s).sum()), int(s.max(initial=0))


def check_detection_memory(features_per_camera, links: Links, limit_gb: float,
                           flag: str = "--max-memory-gb") -> None:
    """InputError if the detection's estimated memory exceeds ``limit_gb`` (module notes)."""
    entries, largest = detection_entries(features_per_camera, links)
    need = entries * BYTES_PER_ENTRY / 1e9
    if need > limit_gb:
        raise InputError(
            f"the links chain up to {largest} features into one association set; the "
            f"distributed detection (every robot holds every feature of its sets, eq. 5) "
            f"would need about {need:.1f} GB, above the limit of {limit_gb:g} GB; such sets "
            f"come from wrong links: clean them first, or raise the limit with {flag}")
