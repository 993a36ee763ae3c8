"""Fixtures of the whole suite."""

import pytest

from data_synth.cache import ENV


@pytest.fixture(scope="session", autouse=True)
def _render_cache_in_tmp(tmp_path_factory):
    """Rendered views are cached in a folder of this test session, never in the user's cache
    (subprocesses inherit the variable)."""
    patch = pytest.MonkeyPatch()
    patch.setenv(ENV, str(tmp_path_factory.mktemp("render-cache")))
    yield
    patch.undo()
