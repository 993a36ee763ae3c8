"""run-images --truth homographies reads its H1to{k}p.txt files on the file names before any
image is decoded: a missing or broken one is refused at once, not after every photograph of
the folder was read."""

import shutil
from pathlib import Path

import pytest

from pipeline.__main__ import main
from pipeline.inputs import photos

GRAF_SMALL = Path(__file__).resolve().parents[2] / "data" / "graffiti_small"


@pytest.fixture
def graffiti(tmp_path):
    folder = tmp_path / "graffiti"
    folder.mkdir()
    for k in range(1, 5):
        shutil.copy(GRAF_SMALL / f"img{k}.png", folder / f"img{k}.png")
    for k in range(2, 5):
        shutil.copy(GRAF_SMALL / f"H1to{k}p.txt", folder / f"H1to{k}p.txt")
    return folder


@pytest.fixture
def no_decoding(monkeypatch):
    def refuse(path):
        raise AssertionError(f"{path} was decoded")

    monkeypatch.setattr(photos, "load_image", refuse)


@pytest.mark.parametrize("damage,message", [
    (lambda f: (f / "H1to3p.txt").unlink(),
     "no homography file H1to3p.txt for image 3 of 4 (name order)"),
    (lambda f: (f / "H1to4p.txt").write_text("1 0 0\n0 1 0\n"),
     "H1to4p.txt: expected an invertible 3 x 3 homography, got shape (2, 3)"),
])
def test_bad_homographies_are_refused_before_any_image_is_decoded(graffiti, tmp_path, capsys,
                                                                  no_decoding, damage,
                                                                  message):
    damage(graffiti)
    out = tmp_path / "run"
    assert main(["run-images", str(graffiti), "--truth", "homographies", "--no-rerun",
                 "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "was decoded" not in err, err
    lines = [ln for ln in err.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1 and message in lines[0], err
    assert not out.exists()
