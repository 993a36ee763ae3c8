"""One line per pipeline stage with its wall time, so a run is never silent for long."""

from __future__ import annotations

import sys
import time
from contextlib import contextmanager

__all__ = ["StageTimer"]


class StageTimer:
    """Times named stages and prints ``[stage] ... done in X s`` lines to ``stream``.

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
        self.stream = stream if stream is not None else sys.stderr
        self.timings: dict[str, float] = {}

    @contextmanager
    def stage(self, name: str, detail: str = ""):
        if self.verbose:
            print(f"[{name}] {detail}".rstrip() + " ...", file=self.stream, flush=True)
        t0 = time.perf_counter()
        yield
        dt = time.perf_counter() - t0
        self.timings[name] = self.timings.get(name, 0.0) + dt
        if self.verbose:
            print(f"[{name}] done in {dt:.2f} s", file=self.stream, flush=True)

    def note(self, text: str) -> None:
        """Print a result line under the current stage."""
        if self.verbose:
            print(f"    {text}", file=self.stream, flush=True)
