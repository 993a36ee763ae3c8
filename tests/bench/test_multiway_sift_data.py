"""multiway --data on a labelled folder of images and keypoints only (no .scf files, which
run-landmarks reads with SIFT at the keypoints) refused it with '--descriptors given needs one
NAME.scf per image ... or use --descriptors sift', an option the bench does not have; it now
reads the folder as run-landmarks does."""

import json

import numpy as np
from benchload import load_bench
from PIL import Image


def write_set(folder, n_images=3, n_landmarks=8):
    rng = np.random.default_rng(0)
    texture = (rng.random((120, 160)) * 255).astype(np.uint8)
    pts = rng.uniform(30, 90, (n_landmarks, 2))
    folder.mkdir()
    for k in range(n_images):  # the same texture shifted: every landmark seen by every image
        shift = 4 * k
        Image.fromarray(np.roll(texture, shift, axis=1)).save(folder / f"view{k}.png")
        np.savetxt(folder / f"view{k}.txt", pts + [shift, 0], fmt="%.2f")


def test_a_set_without_descriptor_files_is_matched_by_sift(tmp_path, capsys):
    data = tmp_path / "set"
    write_set(data)
    out = tmp_path / "bench"
    multiway = load_bench("multiway")
    code = multiway.main(["--data", str(data), "--frames", "3", "--graphs", "complete",
                          "--inputs", "descriptors", "--methods", "sync", "--graffiti", "",
                          "--formations", "", "--team", "--warped-seeds", "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    records = json.loads((out / "results.json").read_text())["records"]
    assert [(r["case"], r["frames"], r["method"]) for r in records] == [("landmarks", 3, "sync")]
