"""StageTimer (stage times, progress lines, freed memory handed back at the end of a stage) and
the progress bars of long stages."""

import io

import pipeline.progress as progress
from pipeline.progress import StageTimer, release_free_memory


def test_stage_times_add_up_and_lines_are_printed():
    out = io.StringIO()
    timer = StageTimer(stream=out)
    for _ in range(2):
        with timer.stage("features", "sift"):
            timer.note("1000 features")
    assert list(timer.timings) == ["features"] and timer.timings["features"] >= 0
    lines = out.getvalue().splitlines()
    assert lines[0] == "[features] sift ..." and lines[1] == "    1000 features"
    assert lines[2].startswith("[features] done in ")


def test_each_stage_end_releases_free_memory(monkeypatch):
    calls = []
    monkeypatch.setattr(progress, "release_free_memory", lambda: calls.append(1))
    timer = StageTimer(verbose=False)
    with timer.stage("a"):
        assert calls == []
    with timer.stage("b"):
        pass
    assert len(calls) == 2
    with StageTimer(verbose=False, release_memory=False).stage("c"):
        pass
    assert len(calls) == 2


def test_release_free_memory_is_safe_to_call():
    blocks = [bytearray(1 << 20) for _ in range(32)]
    del blocks
    assert release_free_memory() in (True, False)


def _terminal():
    f = io.StringIO()
    f.isatty = lambda: True
    return f


def test_progress_off_a_terminal_yields_the_items_without_a_bar(monkeypatch):
    err = io.StringIO()
    monkeypatch.setattr(progress.sys, "stderr", err)
    items = progress.progress([1, 2, 3], desc="features")
    assert list(items) == [1, 2, 3] and err.getvalue() == ""
    with progress.progress(None, total=5, desc="mapping") as bar:  # the calls made on a bar
        bar.update(2)
    assert err.getvalue() == ""


def test_progress_on_a_terminal_draws_a_bar(monkeypatch):
    import logging

    level = progress.log.level
    try:
        term = _terminal()
        monkeypatch.setattr(progress.sys, "stderr", term)
        progress.log.setLevel(logging.INFO)
        assert list(progress.progress(range(3), desc="matching pairs")) == [0, 1, 2]
        assert "matching pairs" in term.getvalue()
        quiet = _terminal()
        monkeypatch.setattr(progress.sys, "stderr", quiet)
        progress.log.setLevel(logging.WARNING)  # --quiet
        assert list(progress.progress(range(3), desc="matching pairs")) == [0, 1, 2]
        assert quiet.getvalue() == ""
    finally:
        progress.log.setLevel(level)


def test_rounds_bar_counts_rounds_on_a_terminal_and_is_silent_otherwise(caplog):
    import logging

    caplog.set_level(logging.INFO, logger="pipeline.progress")
    f = _terminal()
    with progress.rounds_bar("consistency", delay=0, stream=f) as bar:
        bar.set_description_str("consistency: detection 1")
        bar.update(3)
        bar.refresh()  # the counter redraws at most every 0.5 s
    assert "consistency: detection 1: 3 rounds" in f.getvalue()
    quiet = io.StringIO()  # not a terminal
    with progress.rounds_bar("consistency", delay=0, stream=quiet) as bar:
        bar.update(3)
    assert quiet.getvalue() == ""
    caplog.set_level(logging.WARNING, logger="pipeline.progress")  # --quiet
    f = _terminal()
    with progress.rounds_bar("consistency", delay=0, stream=f) as bar:
        bar.update(3)
    assert f.getvalue() == ""


def test_the_c_library_is_looked_up_once_not_at_every_stage_end():
    # each stage end calls release_free_memory; finding and loading libc again each time
    # would put a library lookup on that path
    assert progress._malloc_trim() is progress._malloc_trim()
