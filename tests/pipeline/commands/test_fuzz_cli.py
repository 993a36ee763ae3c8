"""Damaged input files through the command line, each in its own process (``python -m
pipeline``): exit status 0, or 2 with one ``error:`` line, never a traceback; a failed run
leaves no output behind. A few examples per command (each starts Python); the readers' own
fuzz tests (tests/pipeline/*/test_fuzz_*.py) draw many more."""

import sys
import tempfile
from pathlib import Path

import h5py
import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from PIL import Image

sys.path.insert(0, str(Path(__file__).parent))
sys.path.insert(0, str(Path(__file__).parents[1]))
from hostile import run_capped  # noqa: E402
from mutants import bytes_mutant, text_mutant  # noqa: E402

CLI = settings(max_examples=4, deadline=None,
               suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


def _verdict(r, out: Path) -> None:
    assert r.returncode in (0, 2), (r.returncode, r.stderr[-2000:])
    assert "Traceback" not in r.stderr, r.stderr[-2000:]
    if r.returncode == 2:
        errors = [ln for ln in r.stderr.splitlines() if ln.startswith("error: ")]
        assert len(errors) == 1, r.stderr[-2000:]
        assert not out.exists(), "a failed run left its output"


LINKS = "cam_i,feat_i,cam_j,feat_j,quality\n0,0,1,0,0.9\n0,1,2,0,0.5\n1,0,2,1,1\n1,1,2,0,0.25\n"


@CLI
@given(text_mutant(LINKS))
def test_resolve_on_a_damaged_links_file(text):
    with tempfile.TemporaryDirectory() as d:
        src, out = Path(d) / "links.csv", Path(d) / "out.csv"
        src.write_bytes(text.encode("utf-8", "surrogatepass"))
        _verdict(run_capped(["resolve", "--links", src, "--out", out], cwd=d), out)


def _hloc(d: Path) -> tuple[Path, Path]:
    feats, matches = d / "features.h5", d / "matches.h5"
    with h5py.File(feats, "w") as fd:
        for k, name in enumerate(("a.jpg", "b.jpg", "c.jpg")):
            fd.create_group(name).create_dataset(
                "keypoints", data=np.arange(12, dtype=np.float32).reshape(6, 2) + k)
    with h5py.File(matches, "w") as fd:
        for a, b in (("a.jpg", "b.jpg"), ("b.jpg", "c.jpg"), ("a.jpg", "c.jpg")):
            fd.create_group(f"{a}/{b}").create_dataset(
                "matches0", data=np.array([0, 1, 2, 3, -1, 5], np.int32))
    return feats, matches


@CLI
@given(st.sampled_from(["features", "matches"]), st.data())
def test_clean_h5_on_a_damaged_file(which, data):
    with tempfile.TemporaryDirectory() as d:
        feats, matches = _hloc(Path(d))
        path = feats if which == "features" else matches
        path.write_bytes(data.draw(bytes_mutant(path.read_bytes(), max_ops=4)))
        out = Path(d) / "out.h5"
        _verdict(run_capped(["clean-h5", "--features", feats, "--matches", matches,
                             "--out", out, "--no-rerun"], cwd=d), out)


@CLI
@given(st.sampled_from(["a.txt", "b.txt", "a.scf"]), st.data())
def test_run_landmarks_on_a_damaged_label_file(name, data):
    with tempfile.TemporaryDirectory() as d:
        folder = Path(d) / "set"
        folder.mkdir()
        kp = {"a": "10 10\n50 50\n80 20\n", "b": "12 11\n52 49\n79 22\n",
              "c": "9 12\n48 51\n81 21\n"}
        desc = {"a": "-2 1\n0 2\n1 1\n", "b": "1 2\n1 -1\n0 0\n", "c": "-2 0\n1 -1\n0 1\n"}
        for stem in kp:
            Image.new("L", (100, 100), 128).save(folder / f"{stem}.png")
            (folder / f"{stem}.txt").write_text(kp[stem])
            (folder / f"{stem}.scf").write_text(desc[stem])
        valid = (folder / name).read_text()
        (folder / name).write_bytes(data.draw(text_mutant(valid)).encode("utf-8",
                                                                         "surrogatepass"))
        out = Path(d) / "run"
        _verdict(run_capped(["run-landmarks", folder, "--graph", "complete", "--out", out,
                             "--no-baselines"], cwd=d), out)
