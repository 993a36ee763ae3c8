"""bench/graffiti_truth.py: a failed write of results.json leaves the previous one whole."""

import json
import resource
import shutil
import signal
import sys
from pathlib import Path

import pytest
from benchload import load_bench

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data" / "graffiti_small"


def _bench():
    return load_bench("graffiti_truth")


def test_a_write_that_fails_keeps_the_previous_results(tmp_path, monkeypatch):
    photos = tmp_path / "graffiti"
    photos.mkdir()
    for name in ("img1.png", "img2.png", "img3.png", "H1to2p.txt", "H1to3p.txt"):
        shutil.copy(DATA / name, photos / name)
    out = tmp_path / "bench"
    out.mkdir()
    previous = json.dumps({"reports": {"ring": {"kept": list(range(2000))}}})
    (out / "results.json").write_text(previous)
    mod = _bench()
    table = mod.table
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    handler = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)

    def table_then_disk_full(*args):
        text = table(*args)
        # from here on no file of this process may grow past 1000 bytes (EFBIG): the write
        # of results.json fails part-way, as on a full disk
        resource.setrlimit(resource.RLIMIT_FSIZE, (1000, hard))
        return text

    monkeypatch.setattr(mod, "table", table_then_disk_full)
    monkeypatch.setattr(sys, "argv", ["graffiti_truth.py", str(photos), "--graphs", "ring",
                                      "--out", str(out)])
    try:
        with pytest.raises(OSError):
            mod.main()
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
        signal.signal(signal.SIGXFSZ, handler)
    assert (out / "results.json").read_text() == previous
    assert sorted(p.name for p in out.iterdir()) == ["results.json", "ring"]
