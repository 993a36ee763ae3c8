"""One line per pipeline stage with its wall time, so a run is never silent for long."""

from __future__ import annotations

import sys
import threading
import time
from contextlib import contextmanager

__all__ = ["StageTimer", "ticker"]


@contextmanager
def ticker(description: str, delay: float = 2.0, stream=None):
    """Show a tqdm line with the elapsed time while the block runs, if it runs longer than
    ``delay`` seconds (only on a terminal: tqdm stays silent when ``stream`` is not one).

    For stages whose inner loop gives no count to report (the simulated robot network runs
    ``n`` robots for up to ``d + 1`` rounds per detection): it says the run is alive and for
    how long, not how much is left.
    """
    from tqdm import tqdm

    stop = threading.Event()

    def tick():
        if stop.wait(delay):
            return
        with tqdm(desc=description, total=None, unit="s", file=stream or sys.stderr,
                  disable=None, leave=False, ncols=100, bar_format="{desc}: {elapsed}") as bar:
            while not stop.wait(1.0):
                bar.update(1)

    thread = threading.Thread(target=tick, daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join(timeout=2.0)


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
