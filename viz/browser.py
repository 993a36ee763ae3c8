"""Check that a recording shows in the web viewer: ``python -m viz.browser [RUN_DIR | FILE.rrd]``.

Serves the recording as ``make view`` does without a display (:mod:`viz.view`, on free ports),
opens the URL it prints in headless Chromium (Debian's ``chromium``; the page is driven over
the DevTools protocol on a pipe, standard library only), and saves a screenshot once the
recording is drawn. Exit 0 when the view shows the recording, 1 when it stays empty (the
welcome screen, the loading screen, or an empty layout: almost no coloured pixel), 2 when
there is nothing to open or no browser.
"""

from __future__ import annotations

import argparse
import base64
import io
import json
import os
import select
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

__all__ = ["find_browser", "free_port", "screenshot", "shows_recording", "main"]

BROWSERS = ("chromium", "chromium-browser", "google-chrome")
#: share of the screen in coloured pixels above which a view shows a recording: the images,
#: keypoints and links of a run fill a tenth of it or more, the viewer's own screens
#: (welcome, loading, an empty layout) are grey but for a few icons (well below 0.5 %)
MIN_COLOURED_SHARE = 0.02


def find_browser() -> str | None:
    """The first Chromium-like browser on ``PATH``, or None."""
    return next((b for b in map(shutil.which, BROWSERS) if b), None)


def free_port() -> int:
    """A TCP port free on this machine now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def coloured_share(png: bytes) -> float:
    """Share of the pixels of a PNG whose channels differ by more than 60 (not grey)."""
    import numpy as np
    from PIL import Image

    rgb = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=np.int16)
    return float(((rgb.max(axis=2) - rgb.min(axis=2)) > 60).mean())


def shows_recording(png: bytes) -> bool:
    """Whether a screenshot of the viewer shows a recording (:data:`MIN_COLOURED_SHARE`)."""
    return coloured_share(png) >= MIN_COLOURED_SHARE


class _DevTools:
    """Chromium's DevTools protocol over ``--remote-debugging-pipe`` (fd 3 in, fd 4 out,
    NUL-terminated JSON messages)."""

    def __init__(self, browser: str, size: tuple[int, int]):
        self.profile = tempfile.mkdtemp(prefix="formation-match-browser-")
        to_browser, self._write = os.pipe()
        self._read, from_browser = os.pipe()
        args = [browser, "--headless", "--no-sandbox", "--remote-debugging-pipe",
                "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                f"--user-data-dir={self.profile}", f"--window-size={size[0]},{size[1]}",
                "about:blank"]

        def as_fds_3_and_4():  # in the child: the browser reads fd 3 and writes fd 4
            a, b = os.dup(to_browser), os.dup(from_browser)  # neither is 3 or 4 any more
            os.dup2(a, 3)
            os.dup2(b, 4)
            os.set_inheritable(3, True)  # also where a or b already was 3 or 4
            os.set_inheritable(4, True)

        # close_fds=False: only inheritable descriptors pass, i.e. the two made above
        self.proc = subprocess.Popen(args, preexec_fn=as_fds_3_and_4, close_fds=False,
                                     stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                     stderr=subprocess.DEVNULL)
        os.close(to_browser)
        os.close(from_browser)
        self._buf, self._id = b"", 0

    def call(self, method: str, params: dict | None = None, session: str | None = None) -> dict:
        self._id += 1
        msg = {"id": self._id, "method": method, "params": params or {}}
        if session:
            msg["sessionId"] = session
        os.write(self._write, json.dumps(msg).encode() + b"\0")
        while True:
            while b"\0" not in self._buf:
                if not select.select([self._read], [], [], 60.0)[0]:
                    raise RuntimeError(f"the browser did not answer {method} within 60 s")
                chunk = os.read(self._read, 1 << 20)
                if not chunk:
                    raise RuntimeError(f"the browser closed its DevTools pipe ({method})")
                self._buf += chunk
            raw, self._buf = self._buf.split(b"\0", 1)
            reply = json.loads(raw)
            if reply.get("id") == self._id:  # events (no id) are skipped
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply["result"]

    def close(self) -> None:
        self.proc.kill()
        self.proc.wait()
        for fd in (self._read, self._write):
            os.close(fd)
        shutil.rmtree(self.profile, ignore_errors=True)


def screenshot(url: str, timeout_s: float = 60.0, size: tuple[int, int] = (1600, 1000),
               browser: str | None = None, until=shows_recording) -> bytes:
    """PNG of ``url`` in headless Chromium: the first screenshot (taken every 2 s) for which
    ``until(png)`` holds, else the last one after ``timeout_s``.

    Raises
    ------
    FileNotFoundError
        No Chromium-like browser installed.
    """
    browser = browser or find_browser()
    if browser is None:
        raise FileNotFoundError("no headless browser: install Chromium (Debian: "
                                "apt-get install chromium)")
    tools = _DevTools(browser, size)
    try:
        target = tools.call("Target.createTarget", {"url": "about:blank"})["targetId"]
        session = tools.call("Target.attachToTarget", {"targetId": target,
                                                       "flatten": True})["sessionId"]
        tools.call("Emulation.setDeviceMetricsOverride", {
            "width": size[0], "height": size[1], "deviceScaleFactor": 1, "mobile": False},
            session)
        tools.call("Page.navigate", {"url": url}, session)
        end = time.monotonic() + timeout_s
        while True:
            time.sleep(2.0)
            png = base64.b64decode(tools.call("Page.captureScreenshot", {"format": "png"},
                                              session)["data"])
            if until(png) or time.monotonic() > end:
                return png
    finally:
        tools.close()


def main(argv=None) -> int:
    from viz.view import find_recording, viewer_command, web_url

    ap = argparse.ArgumentParser(prog="python -m viz.browser",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("target", nargs="?", default=None, metavar="RUN_DIR|FILE.rrd")
    ap.add_argument("--out", default="viewer.png", help="screenshot (default viewer.png)")
    ap.add_argument("--timeout", type=float, default=90.0,
                    help="seconds to wait for the recording to show (default 90)")
    args = ap.parse_args(argv)
    try:
        path = find_recording(args.target)
    except FileNotFoundError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if find_browser() is None:
        print("error: no headless browser: install Chromium (Debian: apt-get install chromium)",
              file=sys.stderr)
        return 2
    port, grpc_port = free_port(), free_port()
    url = web_url(port, grpc_port)
    server = subprocess.Popen(viewer_command(path, True, port, grpc_port),
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        png = screenshot(url, args.timeout)
    finally:
        server.terminate()
        server.wait()
    Path(args.out).write_bytes(png)
    share = coloured_share(png)
    if share < MIN_COLOURED_SHARE:
        print(f"error: {url} shows no recording after {args.timeout:g} s ({share:.1%} of the "
              f"screen coloured); screenshot in {args.out}", file=sys.stderr)
        return 1
    print(f"{url} shows {path} ({share:.1%} of the screen coloured); screenshot in {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
