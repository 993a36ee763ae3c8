"""``python -m viz.browser`` on an online run's recording (``run-formation --steps``,
``run-images --sequence``): its views are plots of the step figures and a few robots, thin
lines on white that colour 0.2-0.5 % of the views area, below the 0.5 % the check asked for;
it waited its whole timeout and then said the viewer showed no recording (exit 1)."""

from types import SimpleNamespace

import numpy as np
import pytest

from viz.browser import coloured_share, find_browser, free_port, screenshot, serve, stop
from viz.online_log import log_online
from viz.view import web_url


def _one_step_recording(path):
    """The recording of a one-step online run of six robots: plots with a single point."""
    n = 6
    online = SimpleNamespace(step=np.zeros(n, int), robot=np.arange(n))
    ci, cj = np.array([0, 1, 2, 3, 4]), np.array([1, 2, 3, 4, 5])
    online.links = SimpleNamespace(ci=ci, cj=cj, step_added=np.zeros(5, int),
                                   step_cut=np.array([-1, -1, 0, -1, -1]))
    steps = [dict(step=0, links_new=6879, conflictive_features=12, cut=106, cut_history=0,
                  conflictive_sets_after=0, rounds=17, bytes=1_450_000, fusion={"cut": 0})]
    centres = np.stack([np.arange(n, dtype=float), np.zeros(n), np.zeros(n)], axis=1)
    return log_online(path, None, online, steps, centres=centres)


def test_an_online_recording_shows_in_the_headless_browser(tmp_path):
    if find_browser() is None:
        pytest.skip("no Chromium on this machine (Debian: apt-get install chromium)")
    path = _one_step_recording(tmp_path / "recording.rrd")
    port, grpc_port = free_port(), free_port()
    server = serve(path, port, grpc_port)
    try:
        shown = screenshot(web_url(port, grpc_port), timeout_s=60)
    finally:
        stop(server)
    from viz.browser import shows_recording

    assert shows_recording(shown), f"{coloured_share(shown):.3%} of the views area coloured"
