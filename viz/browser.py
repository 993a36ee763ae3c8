"""Check that a recording shows in the web viewer: ``python -m viz.browser [RUN_DIR | FILE.rrd]``.

Serves the recording as ``make view`` does without a display (:mod:`viz.view`, on free ports),
opens the URL it prints in headless Chromium (Debian's ``chromium``; the page is driven over
the DevTools protocol on a pipe, standard library only; no address but this machine's is
reached), and saves a screenshot once the recording is drawn. Exit 0 when the view shows the
recording, 1 when it stays empty (the welcome screen, the loading screen, or an empty layout:
no coloured pixel where the views are drawn), 2 when there is nothing to open or no browser.
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

__all__ = ["find_browser", "free_port", "serve", "stop", "screenshot", "shows_recording",
           "main"]

BROWSERS = ("chromium", "chromium-browser", "google-chrome")
#: where the viewer draws its views, as fractions ``(left, top, right, bottom)`` of the
#: screenshot: between the side panels, below the top bar, above the time panel
VIEWS_AREA = (0.14, 0.05, 0.78, 0.84)
#: share of that area in coloured pixels from which it shows a recording: a run's images,
#: keypoints, links and camera frusta take 1.8 % (three 64x48 noise images, 24 links) to 12 %
#: (formation d) of it, an online run's plots of its step figures (``run-formation --steps``,
#: ``run-images --sequence``: thin lines on white) 0.2 % (one step) to 0.5 %; the viewer's own
#: screens (welcome, loading, an empty layout) none, not one pixel
MIN_COLOURED_SHARE = 0.0005


def find_browser() -> str | None:
    """The first Chromium-like browser on ``PATH``, or None."""
    return next((b for b in map(shutil.which, BROWSERS) if b), None)


def free_port() -> int:
    """A TCP port free on this machine now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def serve(path: Path, port: int, grpc_port: int) -> subprocess.Popen:
    """The web viewer serving ``path`` (:func:`viz.view.viewer_command`), in a process group
    of its own: ``rerun`` runs the viewer as a child process, which :func:`stop` ends too."""
    from viz.view import viewer_command

    return subprocess.Popen(viewer_command(path, True, port, grpc_port), start_new_session=True,
                            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)


def stop(proc: subprocess.Popen) -> None:
    """End ``proc`` and every process of its group (started with ``start_new_session``)."""
    import signal

    for sig in (signal.SIGTERM, signal.SIGKILL):
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            break
        try:
            proc.wait(timeout=5)
            break
        except subprocess.TimeoutExpired:
            continue


def coloured_share(png: bytes, area=VIEWS_AREA) -> float:
    """Share of the pixels of ``area`` (:data:`VIEWS_AREA`) of a PNG whose channels differ by
    more than 60 (not grey)."""
    import numpy as np
    from PIL import Image

    rgb = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=np.int16)
    h, w = rgb.shape[:2]
    left, top, right, bottom = area
    rgb = rgb[int(top * h):int(bottom * h), int(left * w):int(right * w)]
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
                # this machine only (the welcome screen would fetch examples from the web)
                "--host-resolver-rules=MAP * ~NOTFOUND,EXCLUDE localhost",
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
                                     start_new_session=True, stdin=subprocess.DEVNULL,
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
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
                if not select.select([self._read], [], [], 180.0)[0]:
                    raise RuntimeError(f"the browser did not answer {method} within 180 s")
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
        stop(self.proc)
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


def _bad_options(out: str, timeout_s: float) -> str | None:
    """Why the screenshot cannot be written to ``out`` or waited for ``timeout_s`` seconds,
    or None; said before the viewer and the browser start."""
    import math

    from pipeline.errors import InputError
    from pipeline.outputs import check_output_files

    if not (math.isfinite(timeout_s) and timeout_s > 0):
        return f"--timeout {timeout_s:g}: give the seconds to wait, a number > 0 (e.g. 90)"
    try:
        check_output_files([("--out", out)], overwrite=True)  # the default is replaced
    except InputError as exc:
        return str(exc)
    return None


def main(argv=None) -> int:
    from viz.view import TARGET_HELP, parse_with_recording, say, web_url

    ap = argparse.ArgumentParser(prog="python -m viz.browser",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("target", nargs="?", default=None, metavar="RUN_DIR|FILE.rrd",
                    help=TARGET_HELP)
    ap.add_argument("--out", default="viewer.png", help="screenshot (default viewer.png)")
    ap.add_argument("--timeout", type=float, default=90.0,
                    help="seconds to wait for the recording to show (default 90)")
    args, path = parse_with_recording(ap, argv)
    if path is None:
        return 2
    problem = _bad_options(args.out, args.timeout)
    if problem:
        print(f"error: {problem}", file=sys.stderr)
        return 2
    if find_browser() is None:
        print("error: no headless browser: install Chromium (Debian: apt-get install chromium)",
              file=sys.stderr)
        return 2
    port, grpc_port = free_port(), free_port()
    url = web_url(port, grpc_port)
    server = serve(path, port, grpc_port)
    try:
        png = screenshot(url, args.timeout)
    finally:
        stop(server)
    from pipeline.runfolder import atomic_file

    with atomic_file(args.out, "wb", flag="--out") as f:  # a failure leaves --out as it was
        f.write(png)
    share = coloured_share(png)
    if share < MIN_COLOURED_SHARE:
        print(f"error: {url} shows no recording after {args.timeout:g} s ({share:.1%} of the "
              f"views area coloured); screenshot in {args.out}", file=sys.stderr)
        return 1
    say(f"{url} shows {path} ({share:.1%} of the views area coloured); screenshot in {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
