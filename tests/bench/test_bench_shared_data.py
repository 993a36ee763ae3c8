"""Every bench reading the shared data sets looks for them in one place by default:
``../shared/data`` beside the clone, whatever the current folder (some looked in
``../shared/data`` of the current folder, some in ``/work/shared/data``)."""

import argparse
from pathlib import Path

import pytest
from benchload import load_bench

ROOT = Path(__file__).resolve().parents[2]
SHARED = ROOT.parent / "shared" / "data"


class _Parsed(Exception):
    pass


@pytest.mark.parametrize("name, option, data_set", [
    ("landmarks_clear", "data", "cmu_hotel"),
    ("sync_scaling", "data", "cmu_hotel"),
    ("spectral_baselines", "data", "cmu_hotel"),
    ("multiway", "data", "cmu_hotel"),
    ("multiway", "graffiti", "graffiti"),
    ("graffiti_truth", "directory", "graffiti"),
])
def test_the_default_data_is_beside_the_clone(monkeypatch, tmp_path, name, option, data_set):
    monkeypatch.chdir(tmp_path)  # not the clone's parent's folder: nothing of it counts
    parse = argparse.ArgumentParser.parse_args

    def parsed(self, args=None, namespace=None):  # the options as given, then no work
        raise _Parsed(parse(self, args, namespace))
    monkeypatch.setattr(argparse.ArgumentParser, "parse_args", parsed)
    with pytest.raises(_Parsed) as exc:
        load_bench(name).main.__wrapped__([])
    assert Path(getattr(exc.value.args[0], option)) == SHARED / data_set


def test_images_vs_colmap_reads_the_photos_beside_the_clone():
    assert load_bench("images_vs_colmap").DEFAULT_DATA == [SHARED / "sceaux_castle",
                                                          SHARED / "graffiti"]
