"""Settings of the whole test session."""

import os
import shutil
import signal

from hypothesis import settings

from data_synth.cache import ENV
from pipeline.runfolder import make_scratch_folder

# Property tests draw the same examples on every run and machine by default ("repeatable"), so
# a run's verdict does not depend on luck; `pytest --hypothesis-profile explore` draws new
# random examples (and replays failures kept in .hypothesis/) to look for counterexamples.
settings.register_profile("repeatable", derandomize=True)
settings.register_profile("explore", derandomize=False)
settings.load_profile("repeatable")

_saved: dict = {}

# A test run started in the background by a shell without job control (``cmd &`` in a script,
# a CI step) inherits SIGINT ignored, and Python then installs no handler of its own: the
# tests of what a Ctrl-C does (and the programs they start, which inherit it too) saw no
# interrupt and failed. A Ctrl-C is what they test, so the session takes Python's own.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


def pytest_configure(config):
    """Rendered views are cached in a folder of this session, never in the user's cache.

    Set before collection, so the doctests of ``data_synth`` and subprocesses (which inherit
    the variable) use it too; removed with the session, and, of a session that was killed
    (a timeout), by the next one (:func:`pipeline.runfolder.make_scratch_folder`).
    """
    _saved["value"] = os.environ.get(ENV)
    _saved["dir"] = str(make_scratch_folder("formation-match-render-cache-"))
    os.environ[ENV] = _saved["dir"]


def pytest_unconfigure(config):
    if _saved.get("value") is None:
        os.environ.pop(ENV, None)
    else:
        os.environ[ENV] = _saved["value"]
    shutil.rmtree(_saved.get("dir", ""), ignore_errors=True)
