"""Stage lines and progress bars, so a run is never silent for long.

Messages go through :mod:`logging` (logger ``pipeline.progress``): the command line shows
them on stderr at level INFO and hides them with ``--quiet``; a library user configures
logging as usual. Progress bars (:func:`progress`) are tqdm bars on stderr, shown only on a
terminal and only when INFO messages are shown.
"""

from __future__ import annotations

import logging
import sys
import time
from contextlib import contextmanager

__all__ = ["StageTimer", "progress", "log"]

log = logging.getLogger("pipeline.progress")


def progress(iterable, total: int | None = None, desc: str = "", min_items: int = 2):
    """``iterable`` wrapped in a tqdm bar (stderr, cleared when done).

    The bar is off when INFO messages are hidden (``--quiet``), when stderr is not a terminal
    (tqdm's ``disable=None``), or when there are fewer than ``min_items`` items.
    """
    from tqdm.auto import tqdm

    if total is None:
        try:
            total = len(iterable)
        except TypeError:
            total = None
    off = (not log.isEnabledFor(logging.INFO)) or (total is not None and total < min_items)
    return tqdm(iterable, total=total, desc=desc, leave=False, file=sys.stderr,
                disable=True if off else None, dynamic_ncols=True)


class StageTimer:
    """Times named stages and logs ``[stage] ... done in X s`` lines.

    Parameters
    ----------
    verbose : bool
        ``False``: time only, log nothing.
    stream : file, optional
        Write the lines to this stream instead of the ``pipeline.progress`` logger.

    Example
    -------
    >>> timer = StageTimer(verbose=False)
    >>> with timer.stage("render"):
    ...     pass
    >>> list(timer.timings)
    ['render']
    """

    def __init__(self, verbose: bool = True, stream=None):
        self.verbose = verbose
        self.stream = stream
        self.timings: dict[str, float] = {}

    def _emit(self, text: str) -> None:
        if not self.verbose:
            return
        if self.stream is not None:
            print(text, file=self.stream, flush=True)
        else:
            log.info(text)

    @contextmanager
    def stage(self, name: str, detail: str = ""):
        self._emit(f"[{name}] {detail}".rstrip() + " ...")
        t0 = time.perf_counter()
        yield
        dt = time.perf_counter() - t0
        self.timings[name] = self.timings.get(name, 0.0) + dt
        self._emit(f"[{name}] done in {dt:.2f} s")

    def note(self, text: str) -> None:
        """Log a result line under the current stage."""
        self._emit(f"    {text}")

    def warn(self, text: str) -> None:
        """Log a warning (shown even with ``--quiet``)."""
        log.warning("warning: %s", text)
