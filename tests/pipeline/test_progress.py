"""The elapsed-time ticker of long stages."""

import io
import time

from pipeline.progress import ticker


def _terminal():
    f = io.StringIO()
    f.isatty = lambda: True
    return f


def test_ticker_shows_elapsed_time_on_a_terminal_after_its_delay():
    f = _terminal()
    with ticker("consistency stage", delay=0.1, stream=f):
        time.sleep(1.3)
    assert "consistency stage: 00:01" in f.getvalue()


def test_ticker_is_silent_for_short_stages_and_off_a_terminal():
    f = _terminal()
    with ticker("quick", delay=5, stream=f):
        pass
    assert f.getvalue() == ""
    g = io.StringIO()
    with ticker("long", delay=0.1, stream=g):
        time.sleep(0.5)
    assert g.getvalue() == ""
