"""Every bench reading the shared data sets looks for them in one place by default:
``../shared/data`` beside the clone, whatever the current folder (some looked in
``../shared/data`` of the current folder, some in ``/work/shared/data``)."""

from pathlib import Path

import pytest
from benchload import default_options, load_bench

ROOT = Path(__file__).resolve().parents[2]
SHARED = ROOT.parent / "shared" / "data"


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
    assert Path(getattr(default_options(monkeypatch, name), option)) == SHARED / data_set


def test_images_vs_colmap_reads_the_photos_beside_the_clone():
    assert load_bench("images_vs_colmap").DEFAULT_DATA == [SHARED / "sceaux_castle",
                                                          SHARED / "graffiti"]
