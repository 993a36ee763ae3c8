"""The robot program's own helpers (pipeline.team.robot) that need no team running."""

import pstats
from types import SimpleNamespace

import pytest

from pipeline.team.robot import _profiled
from pipeline.team.teamfile import PROFILE_DIR_ENV


def test_the_profile_hook_writes_the_robots_statistics_only_when_asked(tmp_path, monkeypatch):
    team = SimpleNamespace(name="resolve")
    monkeypatch.delenv(PROFILE_DIR_ENV, raising=False)
    assert _profiled(lambda t, i, tr: (t.name, i), team, 3, None) == ("resolve", 3)
    assert list(tmp_path.iterdir()) == []
    monkeypatch.setenv(PROFILE_DIR_ENV, str(tmp_path / "prof"))
    assert _profiled(lambda t, i, tr: sum(range(1000)), team, 3, None) == 499500
    (f,) = (tmp_path / "prof").glob("resolve-3-*.pstats")
    assert pstats.Stats(str(f)).total_calls > 0

    def fails(t, i, tr):
        raise RuntimeError("robot stopped")

    with pytest.raises(RuntimeError, match="robot stopped"):  # written on failure too
        _profiled(fails, SimpleNamespace(name="fusion"), 1, None)
    assert len(list((tmp_path / "prof").glob("fusion-1-*.pstats"))) == 1
