"""Stage lines and progress bars, so a run is never silent for long.

Messages go through :mod:`logging` (logger ``pipeline.progress``): the command line shows
them on stderr at level INFO and hides them with ``--quiet``; a library user configures
logging as usual. Progress bars (:func:`progress`) are tqdm bars on stderr, shown only on a
terminal and only when INFO messages are shown.

At the end of each stage the heap memory it freed is handed back to the operating system
(:func:`release_free_memory`), so that the peak memory of a run is that of its largest stage
rather than the sum of what the allocator kept from every stage.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import logging
import sys
import time
from contextlib import contextmanager

__all__ = ["StageTimer", "progress", "log", "release_free_memory", "rounds_bar",
           "counted"]

log = logging.getLogger("pipeline.progress")


def counted(n: int, word: str) -> str:
    """``n`` and ``word``, in the plural (``s`` added) unless ``n`` is 1.

    >>> counted(1, "step"), counted(2, "step"), counted(0, "link")
    ('1 step', '2 steps', '0 links')
    """
    return f"{n} {word}" if n == 1 else f"{n} {word}s"


@functools.cache
def _malloc_trim():
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        trim = libc.malloc_trim
    except (OSError, AttributeError):  # not glibc: nothing to do
        return None
    trim.argtypes, trim.restype = [ctypes.c_size_t], ctypes.c_int
    return trim


def release_free_memory() -> bool:
    """Return freed heap memory to the operating system; ``True`` if some was released.

    glibc keeps freed blocks for reuse: in one arena per thread, and above a threshold that
    it raises after each large free. After a stage that allocated large temporaries in
    several threads (SIFT scale spaces, say) the process would keep them resident for the
    rest of the run. ``malloc_trim(0)`` releases the free pages of every arena. Without glibc
    this does nothing.
    """
    trim = _malloc_trim()
    return bool(trim(0)) if trim is not None else False


class _NoBar:
    """What :func:`progress` returns when no bar is shown: iterates ``iterable`` and accepts
    the calls made on a tqdm bar (``update``, ``close``, ``with``) as no-ops, so that a run
    whose bar would stay hidden does not import tqdm at all."""

    def __init__(self, iterable=None):
        self.iterable = iterable

    def __iter__(self):
        return iter(self.iterable if self.iterable is not None else ())

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def update(self, n: int = 1) -> None:
        pass

    def set_postfix_str(self, s: str = "", refresh: bool = True) -> None:
        pass

    def set_description_str(self, desc: str = "", refresh: bool = True) -> None:
        pass

    def close(self) -> None:
        pass


def _stream_is_terminal(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):  # no isatty, or a closed stream
        return False


def progress(iterable, total: int | None = None, desc: str = "", min_items: int = 2):
    """``iterable`` wrapped in a tqdm bar (stderr, cleared when done).

    The bar is off when INFO messages are hidden (``--quiet``), when stderr is not a terminal
    (what tqdm's ``disable=None`` would decide), or when there are fewer than ``min_items``
    items; then tqdm is not even imported and a no-op stand-in (:class:`_NoBar`) is returned.
    """
    if total is None:
        try:
            total = len(iterable)
        except TypeError:
            total = None
    off = (not log.isEnabledFor(logging.INFO)) or (total is not None and total < min_items) \
        or not _stream_is_terminal(sys.stderr)
    if off:
        return _NoBar(iterable)
    from tqdm.std import tqdm

    return tqdm(iterable, total=total, desc=desc, leave=False, file=sys.stderr,
                dynamic_ncols=True)


def rounds_bar(description: str, delay: float = 2.0, stream=None):
    """A tqdm counter of rounds (stderr) for the simulated robot network, cleared when done.

    Shown only past ``delay`` seconds, on a terminal and when INFO messages are shown; a
    short run prints nothing, and off a terminal (or with ``--quiet``) tqdm is not imported
    (:class:`_NoBar`). Use as a context manager; the caller names the phase with
    ``set_description_str`` and counts rounds with ``update``.
    """
    stream = stream or sys.stderr
    if not log.isEnabledFor(logging.INFO) or not _stream_is_terminal(stream):
        return _NoBar()
    from tqdm.std import tqdm

    return tqdm(total=None, desc=description, unit=" rounds", file=stream, leave=False,
                delay=delay, dynamic_ncols=True, mininterval=0.5)


class StageTimer:
    """Times named stages and logs ``[stage] ... done in X s`` lines.

    Parameters
    ----------
    verbose : bool
        ``False``: time only, log nothing.
    stream : file, optional
        Write the lines to this stream instead of the ``pipeline.progress`` logger.

    With ``release_memory`` (default) the end of each stage returns freed heap memory to the
    operating system (:func:`release_free_memory`; counted in the stage's time).

    Example
    -------
    >>> timer = StageTimer(verbose=False)
    >>> with timer.stage("render"):
    ...     pass
    >>> list(timer.timings)
    ['render']
    """

    def __init__(self, verbose: bool = True, stream=None, release_memory: bool = True):
        self.verbose = verbose
        self.stream = stream
        self.release_memory = release_memory
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
        if self.release_memory:
            release_free_memory()
        dt = time.perf_counter() - t0
        self.timings[name] = self.timings.get(name, 0.0) + dt
        self._emit(f"[{name}] done in {dt:.2f} s")

    def note(self, text: str) -> None:
        """Log a result line under the current stage."""
        self._emit(f"    {text}")

    def warn(self, text: str) -> None:
        """Log a warning (shown even with ``--quiet``)."""
        log.warning("warning: %s", text)
