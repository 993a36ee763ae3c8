"""The Rerun recording of a team in motion (:mod:`pipeline.runs.online`): a ``step`` timeline.

Reads the results only. On the ``step`` timeline, at every step:

- ``world/robots``: the robots' camera centres at that step (points);
- ``world/links/new``: one strip per frame pair that got links at that step, between the two
  frames' camera centres (``links`` count in the label);
- ``world/links/cut``: one strip per frame pair that lost links at that step;
- ``steps/links_new``, ``steps/cut``, ``steps/conflictive_sets_after``, ``steps/rounds``,
  ``steps/bytes``: the step's figures as scalars (plots); ``steps/cut`` is the consistency
  stage's cuts, ``steps/cut_fusion`` the fusion's (0 where it did not run): together, the links
  ``world/links/cut`` draws;
- ``steps/log``: a text line per step (links arriving, conflicts found, cuts: the consistency
  stage's, and the fusion's where it ran, which ``world/links/cut`` draws too).
"""

from __future__ import annotations

import contextlib
import os
import uuid
from pathlib import Path

import numpy as np
import rerun as rr

from viz.rerun_log import check_recording_whole, record_to_memory, recording_file, write_recording

__all__ = ["log_online", "STEP_SCALARS"]

STEP_SCALARS = ("links_new", "cut", "conflictive_sets_after", "rounds", "bytes")
"""The step record's figures logged as ``steps/<name>`` scalars."""


def _centres(views) -> np.ndarray:
    return np.array([-np.asarray(v.R).T @ np.asarray(v.t).reshape(3) for v in views])


def _pair_strips(centres, ci, cj) -> tuple[list, list]:
    if not len(ci):
        return [], []
    key = np.stack([ci, cj], axis=1)
    pairs, counts = np.unique(key, axis=0, return_counts=True)
    strips = [np.stack([centres[a], centres[b]]) for a, b in pairs.tolist()]
    return strips, [f"{int(c)} link" if c == 1 else f"{int(c)} links" for c in counts]


def log_online(path: str | os.PathLike, sequence, online, steps: list[dict],
               application_id: str = "formation-match", centres=None) -> Path:
    """Write the recording of an online run to ``path`` (temp file, then renamed: a failure
    leaves ``path`` as it was and no temp file).

    ``sequence``: :class:`data_synth.motion.Sequence`; ``online``: the run's
    :class:`pipeline.consistency.engines.online.OnlineAssociation`; ``steps``: its records;
    ``centres``: ``(frames, 3)`` where to draw each frame instead of its camera centre (frames
    without poses, e.g. photographs; ``sequence`` may then be ``None``).
    """
    path = Path(path)
    centres = _centres(sequence.flat.views) if centres is None else np.asarray(centres, float)
    L = online.links
    files = contextlib.ExitStack()
    tmp, sink = files.enter_context(recording_file(path))
    rec = rr.RecordingStream(application_id, recording_id=uuid.uuid4())
    try:
        stream = record_to_memory(rec)
        rec.set_log_time_enabled(False)
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        for r in steps:
            t = int(r["step"])
            rec.set_time("step", sequence=t)
            now = online.step == t
            rec.log("world/robots", rr.Points3D(centres[now], labels=[
                f"robot {int(i)}" for i in online.robot[now]], radii=0.08))
            for name, sel in (("new", L.step_added == t), ("cut", L.step_cut == t)):
                strips, labels = _pair_strips(centres, L.ci[sel], L.cj[sel])
                colour = [60, 160, 255] if name == "new" else [230, 60, 40]
                rec.log(f"world/links/{name}", rr.LineStrips3D(strips, labels=labels or None,
                                                                colors=colour))
            for k in STEP_SCALARS:
                rec.log(f"steps/{k}", rr.Scalars(float(r.get(k, 0))))
            fused = r.get("fusion") or {}
            rec.log("steps/cut_fusion", rr.Scalars(float(fused.get("cut", 0))))
            by_fusion = f", {int(fused.get('cut', 0))} cut by fusion" if fused else ""
            rec.log("steps/log", rr.TextLog(
                f"step {t}: {r['links_new']} links arrive, {r['conflictive_features']} "
                f"conflictive features found, {r['cut']} cut ({r.get('cut_history', 0)} by the "
                f"history check){by_fusion}, {r['conflictive_sets_after']} conflictive sets "
                "after"))
        write_recording(rec, stream, tmp, path)
        check_recording_whole(sink, path)
        os.replace(tmp, path)
    except BaseException:
        rec.disconnect()
        tmp.unlink(missing_ok=True)
        raise
    finally:
        files.close()
    return path
