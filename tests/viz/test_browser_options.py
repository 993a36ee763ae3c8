"""``python -m viz.browser``: a --out it cannot write or a --timeout that is no wait were
found only after the viewer was served and the browser had taken its screenshot (--out a
folder raised IsADirectoryError then; --timeout nan never stopped waiting for a recording
that did not show); both are now said first, and the screenshot is written atomically."""

import pytest
from rrd_files import write_small_recording

import viz.browser as browser


@pytest.fixture
def no_viewer(monkeypatch, tmp_path):
    """A browser said installed; serving or screenshotting fails the test."""
    monkeypatch.setattr(browser, "find_browser", lambda: "/usr/bin/chromium")
    monkeypatch.setattr(browser, "serve", lambda *a, **k: pytest.fail("viewer served"))
    monkeypatch.setattr(browser, "screenshot", lambda *a, **k: pytest.fail("browser started"))
    run = tmp_path / "run"
    run.mkdir()
    write_small_recording(run / "recording.rrd")
    return run


@pytest.mark.parametrize("args, said", [
    (["--timeout", "nan"], "--timeout nan: give the seconds to wait"),
    (["--timeout", "0"], "--timeout 0: give the seconds to wait"),
    (["--out", "FOLDER"], "is a folder"),
    (["--out", ""], "--out '' is empty"),
])
def test_bad_options_are_said_before_the_viewer_starts(no_viewer, tmp_path, capsys, args, said):
    (tmp_path / "shots").mkdir()
    args = [str(tmp_path / "shots") if a == "FOLDER" else a for a in args]
    assert browser.main([str(no_viewer), *args]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and said in err and err.count("\n") == 1, err


def test_the_screenshot_is_written_in_one_rename(no_viewer, tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(browser, "serve", lambda *a, **k: None)
    monkeypatch.setattr(browser, "stop", lambda server: None)
    monkeypatch.setattr(browser, "screenshot", lambda *a, **k: b"png bytes")
    monkeypatch.setattr(browser, "coloured_share", lambda png: 1.0)
    out = tmp_path / "shot.png"
    out.write_bytes(b"old")
    assert browser.main([str(no_viewer), "--out", str(out)]) == 0
    assert out.read_bytes() == b"png bytes"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run", "shot.png"]
