"""run-images, as a hostile user would run it: the photos are never touched, a bad value or
file is one line on stderr (exit 2), images without features are named in a warning."""

import json
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from pipeline.__main__ import main
from pipeline.commgraph import comm_graph
from pipeline.errors import InputError
from pipeline.inputs.photos import exif_focal_px, load_folder

sys.path.insert(0, str(Path(__file__).parent))
from hostile import one_line_error, tree  # noqa: E402


@pytest.fixture
def photos(sceaux_small, tmp_path):
    folder = tmp_path / "photos"
    shutil.copytree(sceaux_small, folder)
    return folder




@pytest.mark.parametrize("where", ["photos", "parent"])
def test_out_onto_the_photos_or_their_parent_is_refused(photos, capsys, where):
    before = tree(photos.parent)
    out = photos if where == "photos" else photos.parent
    assert main(["run-images", str(photos), "--graph", "ring", "--out", str(out)]) == 2
    one_line_error(capsys, "holds the input DIR")
    assert tree(photos.parent) == before


def test_out_holding_the_graph_file_is_refused(photos, tmp_path, capsys):
    (tmp_path / "cfg").mkdir()
    graph = tmp_path / "cfg" / "g.csv"
    graph.write_text("0,1\n1,2\n2,3\n")
    assert main(["run-images", str(photos), "--graph", str(graph), "--out",
                 str(tmp_path / "cfg")]) == 2
    one_line_error(capsys, "holds the input --graph")
    assert graph.read_text() == "0,1\n1,2\n2,3\n"


@pytest.mark.parametrize("threads", ["-5", "0", "100000"])
def test_bad_thread_count_is_refused_before_any_work(photos, tmp_path, capsys, threads):
    assert main(["run-images", str(photos), "--graph", "ring", "--threads", threads,
                 "--out", str(tmp_path / "run")]) == 2
    one_line_error(capsys, f"--threads {threads}")
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("args,message", [
    (["--graph", "knn:0"], "graph 'knn:0': K must be a positive integer"),
    (["--features", "orb"], "--matcher colmap needs SIFT descriptors; --features orb"),
    (["--window", "2"], "--window applies to an online job only; add --sequence"),
    (["--truth-tol", "3"], "--truth-tol 3.0 without --truth"),
    (["--max-size", "10"], "--max-size 10: expected at least 16 pixels of the longest side, "
                           "or 0 for full resolution"),
    (["--max-size", "-1"], "--max-size -1: expected at least 16"),
])
def test_options_that_cannot_run_are_refused_before_any_work(photos, tmp_path, capsys, args,
                                                            message):
    assert main(["run-images", str(photos), *args, "--out", str(tmp_path / "run")]) == 2
    captured = capsys.readouterr()
    assert "[features]" not in captured.err and "[load]" not in captured.err
    assert message in captured.err and "Traceback" not in captured.err
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("fx", ["1e300", "1e-9", "0.5"])
def test_k_with_an_absurd_focal_length_is_refused(photos, tmp_path, capsys, fx):
    (photos / "K.txt").write_text(f"{fx} 0 320\n0 {fx} 240\n0 0 1\n")
    assert main(["run-images", str(photos), "--graph", "ring", "--out",
                 str(tmp_path / "run")]) == 2
    one_line_error(capsys, "not a usable focal length")


def test_graph_naming_a_folder_says_so(photos, tmp_path, capsys):
    (tmp_path / "gdir").mkdir()
    assert main(["run-images", str(photos), "--graph", str(tmp_path / "gdir"), "--out",
                 str(tmp_path / "run")]) == 2
    one_line_error(capsys, "is a folder")


def _jpeg_with_exif(path, unit):
    im = Image.fromarray(np.random.default_rng(0).integers(0, 255, (48, 64, 3), np.uint8))
    exif = Image.Exif()
    ifd = exif.get_ifd(0x8769)
    ifd[0x920A] = 35.0      # FocalLength, mm
    ifd[0xA20E] = 4000.0    # FocalPlaneXResolution
    ifd[0xA210] = unit      # FocalPlaneResolutionUnit
    im.save(path, exif=exif)


def test_exif_unit_that_is_a_string_is_ignored_not_a_traceback(tmp_path):
    for k in range(2):
        _jpeg_with_exif(tmp_path / f"{k}.jpg", "centimetres")
    assert exif_focal_px(Image.open(tmp_path / "0.jpg"), 64, 48) is None
    views = load_folder(tmp_path)
    assert [v.intrinsics_source for v in views] == ["guess", "guess"]


def test_exif_focal_length_no_lens_has_is_ignored(tmp_path):
    for k in range(2):
        _jpeg_with_exif(tmp_path / f"{k}.jpg", 4)  # 4000 px per mm: f = 140,000 px on 64 px
    assert exif_focal_px(Image.open(tmp_path / "0.jpg"), 64, 48) is not None
    assert [v.intrinsics_source for v in load_folder(tmp_path)] == ["guess", "guess"]
    with pytest.raises(InputError, match="no EXIF focal length"):
        load_folder(tmp_path, intrinsics="exif")


def test_graph_file_may_quote_names_with_spaces_commas_and_hashes(tmp_path):
    names = ["a b.jpg", "c,d.jpg", "#e.jpg", 'say "hi".jpg']
    g = tmp_path / "g.csv"
    g.write_text('cam_i,cam_j\n"a b.jpg","c,d.jpg"  # a comment\n"c,d.jpg"\t"#e.jpg"\n'
                 '# a comment line\n"#e.jpg", "say ""hi"".jpg"\n3 0\n')
    assert comm_graph(g, names).tolist() == [[0, 1], [0, 3], [1, 2], [2, 3]]


def test_images_without_features_are_named_in_a_warning(photos, tmp_path, capsys):
    (photos / "K.txt").unlink()  # one K cannot fit these odd sizes: EXIF or the guess
    Image.fromarray(np.full((480, 640, 3), 128, np.uint8)).save(photos / "z_blank.png")
    Image.fromarray(np.zeros((10, 10), np.uint8)).save(photos / "z_tiny.png")
    Image.fromarray(np.random.default_rng(0).integers(0, 255, (16, 8496), np.uint8)).save(
        photos / "z_strip.png")
    out = tmp_path / "run"
    code = main(["run-images", str(photos), "--graph", "ring", "--max-size", "320",
                 "--no-rerun", "--no-fusion", "--out", str(out)])
    report = json.loads((out / "report.json").read_text())
    empty = [im["name"] for im, m in zip(report["images"], report["features_per_camera"],
                                         strict=True) if m == 0]
    assert set(empty) >= {"z_blank.png", "z_tiny.png"}  # the case this test is about
    warning = next(w for w in report["warnings"] if w["code"] == "no-features")
    assert all(name in warning["message"] for name in empty)
    err = capsys.readouterr().err
    assert "warning: no features found" in err and "z_blank.png" in err
    assert code in (0, 3)  # warnings alone do not change the exit code
    assert code == (3 if report["after"]["conflictive_sets"] else 0)


def test_ctrl_c_is_one_line_exit_130_and_nothing_written(photos, tmp_path, capsys,
                                                         monkeypatch):
    import pipeline.stages as run

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(run, "extract_and_match", interrupted)
    before = tree(photos)
    assert main(["run-images", str(photos), "--graph", "ring", "--out",
                 str(tmp_path / "run")]) == 130
    err = capsys.readouterr().err
    assert err.splitlines()[-1].startswith("interrupted:") and "Traceback" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["photos"]
    assert tree(photos) == before


def _jpeg_header(width: int, height: int) -> bytes:
    """The start of a JPEG declaring ``width`` x ``height`` (up to its first scan)."""
    import io

    buf = io.BytesIO()
    Image.fromarray(np.zeros((16, 16, 3), np.uint8)).save(buf, "JPEG")
    data = bytearray(buf.getvalue())
    k = data.find(b"\xff\xc0")
    data[k + 5:k + 7], data[k + 7:k + 9] = height.to_bytes(2, "big"), width.to_bytes(2, "big")
    sos = data.find(b"\xff\xda")
    return bytes(data[:sos + 2 + int.from_bytes(data[sos + 2:sos + 4], "big")])


@pytest.mark.parametrize("width,height,size,needle", [
    (640, 480, 2**30, "1,073,741,824 bytes for a 640x480 image"),   # a 1 GB sparse file
    (12000, 12000, 2**30, "declares 12000x12000 = 144,000,000 pixels"),
    # above Pillow's own bomb limit (about 179 M pixels) Pillow's message came instead
    (20000, 20000, 2**30, "declares 20000x20000 = 400,000,000 pixels"),
], ids=["sparse-1GB", "144-megapixels", "400-megapixels"])
def test_an_image_file_is_judged_on_its_header_before_decoding(photos, tmp_path, capsys,
                                                               monkeypatch, width, height,
                                                               size, needle):
    """Decoding a 1 GB file behind a JPEG header took 42 s before it was refused."""
    from PIL import ImageFile

    big = photos / "000_big.jpg"  # the first in name order
    with open(big, "wb") as f:
        f.write(_jpeg_header(width, height))
        f.truncate(size)
    stat = big.stat()
    monkeypatch.setattr(ImageFile.ImageFile, "load",
                        lambda self: pytest.fail("an image was decoded before the check"))
    assert main(["run-images", str(photos), "--graph", "ring", "--out",
                 str(tmp_path / "run")]) == 2
    one_line_error(capsys, "000_big.jpg", needle)
    assert big.stat().st_mtime_ns == stat.st_mtime_ns and not (tmp_path / "run").exists()


def test_a_live_viewer_that_cannot_be_reached_is_refused_before_any_work(photos, tmp_path,
                                                                         capsys, monkeypatch):
    """--spawn without a display, --connect where no viewer answers or to a malformed URL:
    one line, exit 2, nothing written (Rerun itself would ignore the spawn or retry in the
    background and drop the stream, with its own log lines)."""
    import socket

    from pipeline.commands.run_images import check_live

    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()  # nothing listens there now
    for flags, message in ((["--spawn"], "--spawn needs a display"),
                           (["--connect", f"rerun+http://127.0.0.1:{port}/proxy"],
                            "no Rerun viewer answers there"),
                           (["--connect", "http://127.0.0.1:9876"], "expected Rerun's form"),
                           (["--connect", "--no-rerun"], "--connect with --no-rerun")):
        assert main(["run-images", str(photos), *flags, "--out", str(tmp_path / "run")]) == 2
        one_line_error(capsys, message)
        assert not (tmp_path / "run").exists()
    with socket.socket() as listening:  # a viewer's port that answers passes
        listening.bind(("127.0.0.1", 0))
        listening.listen()
        check_live(False, f"rerun+http://127.0.0.1:{listening.getsockname()[1]}/proxy")
    monkeypatch.setenv("DISPLAY", ":0")
    check_live(True, None)


@pytest.mark.parametrize("args,flag", [
    (["--out", ""], "--out"), (["--intrinsics", ""], "--intrinsics"),
    (["--sequence", "--out", ""], "--out")])
def test_an_empty_out_or_intrinsics_is_refused(photos, tmp_path, monkeypatch, capsys, args,
                                               flag):
    """An empty --out (an unset variable) fell back to the default runs/images-...,
    replacing the run there; an empty --intrinsics was read as the file '.'."""
    monkeypatch.chdir(tmp_path)
    assert main(["run-images", str(photos), *args]) == 2
    one_line_error(capsys, f"{flag} '' is empty (an unset variable?)")
    assert not (tmp_path / "runs").exists()


@pytest.mark.parametrize("extra", [[], ["--sequence"]])
def test_an_empty_dir_is_refused_not_read_as_the_current_folder(tmp_path, monkeypatch, capsys,
                                                                 extra):
    monkeypatch.chdir(tmp_path)
    assert main(["run-images", "", *extra]) == 2
    one_line_error(capsys, "DIR '' is empty (an unset variable?); give a folder name")


def test_intrinsics_naming_a_folder_says_so(photos, tmp_path, capsys):
    assert main(["run-images", str(photos), "--intrinsics", str(tmp_path),
                 "--out", str(tmp_path / "run")]) == 2
    one_line_error(capsys, f"intrinsics file {str(tmp_path)!r} is a folder; give the K.txt file")


def test_an_out_name_that_is_not_utf8_is_written_with_its_recording(photos, tmp_path):
    """A Latin-1 --out ('run\\xe9') was refused ('the recording cannot be written there'),
    with --no-rerun too, where every other command writes its run. Run as its own process:
    its lines name the path, which is not UTF-8 text, and pytest-xdist sends captured lines
    between its processes as UTF-8."""
    import os
    import subprocess

    out = os.path.join(os.fsencode(tmp_path), b"run\xe9")
    root = Path(__file__).resolve().parents[3]
    proc = subprocess.run([sys.executable, "-m", "pipeline", "run-images", str(photos), "--out",
                           out, "--max-features", "300"], cwd=root, capture_output=True,
                          env={**os.environ, "LC_ALL": "C.UTF-8"}, timeout=600)
    assert proc.returncode in (0, 3), proc.stderr[-2000:]
    assert {b"report.json", b"links.csv", b"recording.rrd"} <= set(os.listdir(out))


def test_a_refused_run_with_the_default_out_creates_nothing(tmp_path, monkeypatch, capsys):
    """In a folder holding only a sub-folder of images, `run-images . -q` is refused (no image
    directly in DIR); the default --out's runs/ was made first and left behind, empty."""
    sub = tmp_path / "sub"
    sub.mkdir()
    rng = np.random.default_rng(0)
    for k in range(2):
        Image.fromarray(rng.integers(0, 255, (48, 64), dtype=np.uint8)).save(sub / f"f{k}.png")
    monkeypatch.chdir(tmp_path)
    assert main(["run-images", ".", "-q"]) == 2
    assert "no images in '.'" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sub"]
