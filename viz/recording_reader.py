"""Reading a written ``.rrd`` recording back: which entities it holds and how many link strips.

Used to check a recording against its run's ``report.json`` and ``links.csv`` (the tests do);
never needed to write one (:mod:`viz.rerun_log`).
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["entity_paths", "count_strips"]


def entity_paths(path: str | os.PathLike) -> list[str]:
    """Entity paths stored in a recording, e.g. ``['/world', '/world/links/kept', …]``."""
    from rerun.chunk import RrdReader

    return list(RrdReader(Path(path)).store().schema().entity_paths())


def count_strips(path: str | os.PathLike, entity: str) -> int:
    """Number of line strips an entity holds in a recording (0 if the entity is absent).

    Reads the static ``LineStrips3D``/``LineStrips2D`` row of ``entity`` (the last one if it was
    logged more than once). Used to check ``world/links/deleted`` against ``report.json``.
    """
    from rerun.chunk import RrdReader

    entity = "/" + entity.strip("/")
    chunks = RrdReader(Path(path)).store().stream().filter(content=entity, is_static=True).to_chunks()
    count = 0
    for chunk in chunks:
        if chunk.entity_path != entity:
            continue
        batch = chunk.to_record_batch()
        cols = [c for c in batch.schema.names if c.endswith(":strips")]
        for c in cols:
            rows = batch.column(c).to_pylist()
            if rows:
                count = len(rows[-1] or [])
    return count
