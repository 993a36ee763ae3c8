"""Descriptor tables of a labelled-landmark folder whose values are finite but too large for
a distance in float64: refused when read, naming the file, the label row and the value."""

from pathlib import Path

import numpy as np
from PIL import Image

from pipeline.__main__ import main

PTS = np.array([[10.0, 12.0], [30.0, 20.0], [50.0, 40.0], [20.0, 35.0], [40.0, 8.0]])


def _folder(d: Path, huge: float | None) -> Path:
    d.mkdir()
    for k in range(3):
        rng = np.random.default_rng(k)
        Image.fromarray(rng.integers(0, 255, (48, 64), dtype=np.uint8)).save(d / f"v{k}.png")
        np.savetxt(d / f"v{k}.txt", PTS + k)
        desc = rng.normal(size=(len(PTS), 6))  # signed: compared by L2
        if huge is not None and k == 1:
            desc[3, 2] = huge
        np.savetxt(d / f"v{k}.scf", desc)
    return d


def _run(tmp_path, capsys, folder):
    out = tmp_path / "run"
    code = main(["run-landmarks", str(folder), "--out", str(out), "--no-baselines", "--quiet"])
    return code, capsys.readouterr(), out


def test_ordinary_signed_descriptors_are_matched(tmp_path, capsys):
    code, captured, out = _run(tmp_path, capsys, _folder(tmp_path / "in", None))
    assert code == 0 and (out / "links.csv").exists(), captured.err


def test_a_descriptor_whose_square_overflows_is_refused_not_a_traceback(tmp_path, capsys):
    # 1e200 squared is inf in float64: the L2 cost matrix held nan and scipy's Hungarian
    # stopped with 'ValueError: cost matrix is infeasible' (or 'invalid numeric entries')
    folder = _folder(tmp_path / "in", 1e200)
    code, captured, out = _run(tmp_path, capsys, folder)
    assert code == 2 and not out.exists() and "Traceback" not in captured.err
    assert captured.err.strip().splitlines()[-1] == (
        f"error: {folder / 'v1.scf'}: descriptor row 4 holds 1e+200, too large to compare (the "
        "distance of descriptors of 6 values overflows above 2.74e+153); the file is damaged "
        "or in other units: rescale it")
