"""The on-disk render cache: hits give the rendered views bit for bit and render nothing;
bad entries are ignored and rewritten; it lives where the user's environment says."""

from pathlib import Path

import numpy as np
import pytest

import data_synth
from data_synth import cache

SIZE = (96, 72)


@pytest.fixture
def cache_dir(tmp_path, monkeypatch) -> Path:
    d = tmp_path / "cache"
    monkeypatch.setenv(cache.ENV, str(d))
    return d


def _fail(*args, **kwargs):
    raise AssertionError("rendered although the views are cached")


def _same_views(f, g):
    assert f.name == g.name and f.graph == g.graph and f.seed == g.seed
    np.testing.assert_array_equal(f.comm_edges, g.comm_edges)
    np.testing.assert_array_equal(f.centres, g.centres)
    for a, b in zip(f.views, g.views, strict=True):
        assert a.name == b.name
        for field in ("image", "depth", "K", "R", "t"):
            x, y = getattr(a, field), getattr(b, field)
            assert x.dtype == y.dtype and x.shape == y.shape, field
            assert x.tobytes() == y.tobytes(), field


def test_hit_gives_the_rendered_views_without_rendering(cache_dir, monkeypatch):
    fresh = data_synth.render("c", seed=2, size=SIZE, cache=False)
    assert not cache_dir.exists()  # cache=False neither reads nor writes
    first = data_synth.render("c", seed=2, size=SIZE)
    assert list(cache_dir.glob("*.npz")) == [cache.entry_path(2, SIZE, 6)]
    _same_views(fresh, first)

    monkeypatch.setattr(data_synth, "render_view", _fail)
    monkeypatch.setattr(data_synth, "build_scene", _fail)
    _same_views(fresh, data_synth.render("c", seed=2, size=SIZE))
    # another graph on the same robots shares the images: the same entry
    d = data_synth.render("d", seed=2, size=SIZE)
    assert d.name == "d" and len(d.comm_edges) == 15
    np.testing.assert_array_equal(d.views[3].image, fresh.views[3].image)
    assert len(list(cache_dir.glob("*.npz"))) == 1
    # another size or number of robots is another entry
    with pytest.raises(AssertionError, match="rendered although"):
        data_synth.render("c", seed=2, size=(SIZE[0] + 2, SIZE[1]))
    with pytest.raises(AssertionError, match="rendered although"):
        data_synth.render("c", seed=2, size=SIZE, n_robots=5)


def test_one_camera_is_read_alone_and_equals_its_slice(cache_dir, monkeypatch):
    fresh = data_synth.render("d", seed=2, size=SIZE)
    for i in (0, 3, 5):
        one = cache.load_view(2, SIZE, 6, i)
        assert one["image"].tobytes() == fresh.views[i].image.tobytes()
        assert one["depth"].tobytes() == fresh.views[i].depth.tobytes()
    assert cache.load_view(2, SIZE, 6, 6) is None
    assert cache.load_view(2, SIZE, 5, 0) is None  # no such entry
    monkeypatch.setattr(data_synth, "render_view", _fail)
    view, _ = data_synth.render_robot(4, "d", seed=2, size=SIZE)
    assert view.image.tobytes() == fresh.views[4].image.tobytes()
    # a damaged entry: no view, never a wrong one
    path = cache.entry_path(2, SIZE, 6)
    path.write_bytes(path.read_bytes()[:len(path.read_bytes()) // 2])
    assert cache.load_view(2, SIZE, 6, 5) is None


def test_scene_is_built_on_demand(cache_dir):
    f = data_synth.render("a", seed=1, size=SIZE)
    assert "crate2.corner1" in f.scene.landmarks
    assert f.scene is data_synth.build_scene(1)


@pytest.mark.parametrize("damage", ["garbage", "truncated", "empty", "wrong-shape"])
def test_bad_entry_is_ignored_and_rewritten(cache_dir, damage):
    good = data_synth.render("a", seed=1, size=SIZE)
    path = cache.entry_path(1, SIZE, 6)
    data = path.read_bytes()
    if damage == "garbage":
        path.write_bytes(b"not a zip file at all" * 100)
    elif damage == "truncated":
        path.write_bytes(data[:len(data) // 2])
    elif damage == "empty":
        path.write_bytes(b"")
    else:
        arrays = cache.load_views(1, SIZE, 6)
        arrays["depth"] = arrays["depth"][:, :-1]
        np.savez(path, key=np.array(cache._key(1, SIZE, 6)), **arrays)
    assert cache.load_views(1, SIZE, 6) is None
    again = data_synth.render("a", seed=1, size=SIZE)
    _same_views(good, again)
    assert cache.load_views(1, SIZE, 6) is not None  # rewritten
    assert not list(cache_dir.glob(".tmp-*"))


def test_entry_of_other_code_is_not_read(cache_dir, monkeypatch):
    data_synth.render("a", seed=1, size=SIZE)
    old = cache.entry_path(1, SIZE, 6)
    monkeypatch.setattr(cache, "code_version", lambda: "0123456789abcdef")
    assert cache.entry_path(1, SIZE, 6) != old
    assert cache.load_views(1, SIZE, 6) is None
    old.rename(cache.entry_path(1, SIZE, 6))  # right name, wrong key inside
    assert cache.load_views(1, SIZE, 6) is None


@pytest.mark.parametrize("value", ["off", "0", "OFF", "false", ""])
def test_cache_can_be_turned_off(tmp_path, monkeypatch, value):
    monkeypatch.setenv(cache.ENV, value)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert cache.cache_dir() is None
    data_synth.render("a", seed=1, size=SIZE)
    assert not list(tmp_path.rglob("*.npz"))


def test_cache_folder_follows_xdg_then_home(tmp_path, monkeypatch):
    monkeypatch.delenv(cache.ENV)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache.cache_dir() == tmp_path / "xdg" / "formation-match"
    monkeypatch.setenv("XDG_CACHE_HOME", "relative/ignored")
    (tmp_path / "home").mkdir()
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert cache.cache_dir() == tmp_path / "home" / ".cache" / "formation-match"
    monkeypatch.delenv("XDG_CACHE_HOME")
    assert cache.cache_dir() == tmp_path / "home" / ".cache" / "formation-match"


def _no_home(cls):
    raise RuntimeError("Could not determine home directory.")  # as pathlib says it


@pytest.mark.parametrize("home", ["", "missing", None])
def test_no_home_folder_turns_the_cache_off(tmp_path, monkeypatch, home):
    # HOME='' put the cache in /.cache, HOME=/nonexistent made that folder, and HOME unset for
    # a user without a password entry (a container's --user 12345) ended run-formation with
    # "RuntimeError: Could not determine home directory"
    monkeypatch.delenv(cache.ENV)
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    if home is None:
        monkeypatch.delenv("HOME")
        monkeypatch.setattr(Path, "home", classmethod(_no_home))
    else:
        monkeypatch.setenv("HOME", str(tmp_path / home) if home else "")
    assert cache.cache_dir() is None
    assert cache.save_views(1, SIZE, {"image": np.zeros((2, 4, 4, 3), np.uint8)}) is None
    assert not (tmp_path / "missing").exists()


def test_unwritable_cache_is_not_fatal(tmp_path, monkeypatch):
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    monkeypatch.setenv(cache.ENV, str(blocker / "cache"))
    f = data_synth.render("a", seed=1, size=SIZE)
    assert len(f.views) == 6


def _entry(folder: Path, name: str, size: int, mtime: float, key: str | None = None) -> Path:
    """A file written the way the cache writes (``key`` stored first; default: its name)."""
    import os

    path = folder / name
    with open(path, "wb") as f:
        np.savez(f, key=np.array(key or name.removesuffix(".npz")),
                 image=np.zeros(size, np.uint8))
    os.utime(path, (mtime, mtime))
    return path


def _name(k: int) -> str:
    return f"views-seed{k}-96x72-n6-{k:016x}.npz"


def test_prune_removes_least_recently_used_entries_down_to_the_cap(tmp_path):
    old = _entry(tmp_path, _name(1), 400, 1_000)
    mid = _entry(tmp_path, _name(2), 400, 2_000)
    new = _entry(tmp_path, _name(3), 400, 3_000)
    one = old.stat().st_size
    removed = cache.prune(tmp_path, limit=int(2.5 * one))
    assert removed == [old]
    assert mid.exists() and new.exists()
    # the entry just written is kept even when it alone exceeds the cap
    removed = cache.prune(tmp_path, keep=mid, limit=100)
    assert removed == [new] and mid.exists()


def test_prune_removes_only_stale_temporary_files(tmp_path):
    import time

    stale = _entry(tmp_path, f".{_name(1)[:-4]}.tmp-abc.npz", 10, time.time() - 7200,
                   key=_name(1)[:-4])
    live = _entry(tmp_path, f".{_name(1)[:-4]}.tmp-def.npz", 10, time.time(),
                  key=_name(1)[:-4])
    assert cache.prune(tmp_path, limit=10**9) == [stale]
    assert live.exists()


def test_prune_never_touches_a_users_files_in_the_cache_folder(tmp_path):
    """FORMATION_MATCH_CACHE may name a user's folder: only the cache's own files go."""
    import os
    import time

    old = time.time() - 10 * 86400
    users = [_entry(tmp_path, "results.npz", 4000, old),          # any .npz of the user's
             _entry(tmp_path, ".tmp-x.npz", 4000, old),             # the old temporary name
             _entry(tmp_path, _name(7), 4000, old, key="mine"),     # an entry's name only
             _entry(tmp_path, f".{_name(8)[:-4]}.tmp-1.npz", 4000, old, key="mine")]
    (tmp_path / _name(9)).write_bytes(b"\0" * 4000)                # not even an npz
    target = _entry(tmp_path, "precious.npz", 4000, old)
    (tmp_path / _name(5)).symlink_to(target)                       # a link named as an entry
    users += [tmp_path / _name(9), target]
    os.utime(tmp_path / _name(5), (old, old), follow_symlinks=False)
    assert cache.prune(tmp_path, limit=0) == []
    assert all(p.exists() for p in users) and (tmp_path / _name(5)).is_symlink()


def test_entries_written_by_the_cache_are_its_own(cache_dir):
    data_synth.render("a", seed=1, size=SIZE)
    entry = cache.entry_path(1, SIZE, 6)
    assert cache.prune(cache_dir, limit=0) == [entry]


def test_a_hit_marks_its_entry_used_and_a_write_prunes_to_the_cap(cache_dir, monkeypatch):
    import os

    data_synth.render("a", seed=1, size=SIZE)
    first = cache.entry_path(1, SIZE, 6)
    os.utime(first, (1_000, 1_000))
    assert cache.load_views(1, SIZE, 6) is not None
    assert first.stat().st_mtime > 1_000  # the hit marked it used
    # a cap smaller than two entries: writing a second one evicts the first
    monkeypatch.setenv(cache.MAX_MB_ENV, str(first.stat().st_size * 1.5 / 2**20))
    data_synth.render("a", seed=2, size=SIZE)
    assert not first.exists() and cache.entry_path(2, SIZE, 6).exists()


@pytest.mark.parametrize("value", ["", "lots", "-3", "nan", "inf"])
def test_a_meaningless_cap_falls_back_to_the_default(monkeypatch, value):
    monkeypatch.setenv(cache.MAX_MB_ENV, value)
    assert cache.max_bytes() == cache.DEFAULT_MAX_MB * 2**20
