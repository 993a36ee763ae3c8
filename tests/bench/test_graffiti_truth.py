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


def test_relative_paths_are_the_callers(tmp_path, monkeypatch, capsys):
    """run-images runs in the repository: a relative folder or --out was read there (the
    run was written inside the repository, and its report not found)."""
    photos = tmp_path / "graffiti"
    photos.mkdir()
    for name in ("img1.png", "img2.png", "img3.png", "H1to2p.txt", "H1to3p.txt"):
        shutil.copy(DATA / name, photos / name)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "argv", ["graffiti_truth.py", "graffiti", "--graphs", "ring",
                                      "--out", "bench"])
    assert _bench().main() == 0
    report = json.loads((tmp_path / "bench" / "results.json").read_text())["reports"]["ring"]
    assert (tmp_path / "bench" / "ring" / "report.json").is_file() and report["comm_edges"]
    assert report["comm_edges"] == json.loads(
        (tmp_path / "bench" / "ring" / "report.json").read_text())["comm_edges"]


def test_an_unknown_graph_kind_is_refused_before_any_run(tmp_path, monkeypatch, capsys):
    """It ran the graphs before it, then passed run-images' refusal through with exit 1."""
    mod = _bench()

    def no_run(*args):
        raise AssertionError("run-images ran before --graphs was checked")
    monkeypatch.setattr(mod, "run_graph", no_run)
    assert mod.main([str(DATA), "--graphs", "ring", "foo", "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: graph 'foo': not one of line, ring") and err.count("\n") == 1
    assert not (tmp_path / "b").exists()


def test_a_refusal_of_run_images_is_exit_2_in_one_line(tmp_path, capsys):
    """run-images' own refusals (here: one photo, no pair) passed through with exit 1."""
    photos = tmp_path / "graffiti"
    photos.mkdir()
    for name in ("img1.png", "H1to2p.txt"):
        shutil.copy(DATA / name, photos / name)
    code = _bench().main([str(photos), "--graphs", "ring", "--out", str(tmp_path / "b")])
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith("error: ") and err.count("\n") == 1 and "exited" not in err


def test_a_graph_file_runs_in_a_folder_named_by_its_stem(tmp_path, monkeypatch, capsys):
    """``--graphs FILE``: the run folder was ``out / FILE`` (the graph file's own path when
    absolute, refused as holding the input; nested folders when relative, read in the
    repository); it is now named by the file's stem, as run-images names it, and a relative
    file is the caller's."""
    photos = tmp_path / "graffiti"
    photos.mkdir()
    for name in ("img1.png", "img2.png", "img3.png", "H1to2p.txt", "H1to3p.txt"):
        shutil.copy(DATA / name, photos / name)
    (tmp_path / "chain.txt").write_text("img1.png,img2.png\nimg2.png,img3.png\n")
    monkeypatch.chdir(tmp_path)
    assert _bench().main([str(photos), "--graphs", "chain.txt", "--out", "bench"]) == 0
    report = json.loads((tmp_path / "bench" / "results.json").read_text())["reports"]
    assert len(report[str(tmp_path / "chain.txt")]["comm_edges"]) == 2
    assert (tmp_path / "bench" / "chain" / "report.json").is_file()
