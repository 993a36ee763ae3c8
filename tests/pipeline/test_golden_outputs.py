"""Regression guard: the run outputs of formations a–d, ``resolve`` and ``run-images`` on
Sceaux are those recorded in ``tests/data/golden_outputs.json``.

A change that is meant to alter results (a new default, a better stage) re-records them with
``FORMATION_MATCH_RECORD_GOLDEN=1 pytest tests/pipeline/test_golden_outputs.py`` and says in
its commit message which figures moved and why. Every other change must leave them alone.

What is exact and what is compared to a tolerance (the guard must pass on any machine of this
kind, not only on the one that recorded it):

- **Exact:** ``links.csv`` byte for byte (its SHA-256: every link's decision), the per-reason
  link counts, and in ``report.json`` every integer, boolean, string, ``null`` and the shape of
  every list and object — the decisions, counts, rounds, messages and bytes.
- **To a tolerance:** every real number of ``report.json`` (precision, errors, distances,
  ratios) is compared with ``math.isclose(rel_tol=REL_TOL, abs_tol=ABS_TOL)``. These come out
  of floating-point library code (OpenBLAS kernels, OpenCV's SIMD paths, pycolmap) whose last
  bits depend on the CPU the run is on; the same code run twice on one machine gives the same
  bits, another CPU may not. The tolerance is far above such rounding and far below any change
  a decision would cause (one link of a thousand moves a precision by 1e-3).

Left out of the comparison: ``timings_s``, ``versions``, and temporary paths (replaced by
placeholders so the record does not depend on where pytest put them).
"""

from __future__ import annotations

import csv
import hashlib
import json
import math
import os
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest

from pipeline.__main__ import main
from pipeline.runs.formation import FormationConfig, run_formation

GOLDEN = Path(__file__).resolve().parents[1] / "data" / "golden_outputs.json"
RECORD = os.environ.get("FORMATION_MATCH_RECORD_GOLDEN") == "1"
SMALL = dict(seed=0, size=(320, 240), max_features=600, rerun=False)
REL_TOL = 1e-6  # relative tolerance on report.json's real numbers (see the module docstring)
ABS_TOL = 1e-9  # absolute, for real numbers near zero (e.g. a disagreement of 2e-15)


def _digest(run_dir: Path, *paths: Path):
    """Digest of ``run_dir``'s links.csv and report.json; ``paths`` (temporary folders) are
    replaced by placeholders so the record does not depend on where pytest put them."""
    links_name, report_name = "links.csv", "report.json"
    links = (run_dir / links_name).read_bytes()
    with open(run_dir / links_name, newline="") as f:
        counts = Counter(f"{r['status']}:{r['reason']}" for r in csv.DictReader(f))
    record = {"links_sha256": hashlib.sha256(links).hexdigest(),
              "links_by_reason": dict(sorted(counts.items()))}
    report_path = run_dir / report_name
    if report_path.is_file():
        report = json.loads(report_path.read_text())
        for key in ("timings_s", "versions"):
            report.pop(key, None)
        canonical = json.dumps(report, sort_keys=True)
        for k, path in enumerate(paths):
            canonical = canonical.replace(str(path), f"<path{k}>")
        record["report"] = json.loads(canonical)
    return record


def _differences(got, want, where: str = "report") -> list[str]:
    """Where ``got`` differs from ``want``: exactly for everything but real numbers, which
    may differ by ``REL_TOL`` / ``ABS_TOL``. An int recorded where a float is found (or the
    other way round) is a difference: the type is part of the record."""
    if isinstance(want, float) and isinstance(got, float):
        if math.isnan(want) and math.isnan(got):
            return []
        if math.isclose(got, want, rel_tol=REL_TOL, abs_tol=ABS_TOL):
            return []
        return [f"{where}: {got!r} != {want!r} (beyond rel {REL_TOL:g} / abs {ABS_TOL:g})"]
    if type(got) is not type(want):
        return [f"{where}: {got!r} ({type(got).__name__}) != {want!r} ({type(want).__name__})"]
    if isinstance(want, dict):
        if got.keys() != want.keys():
            return [f"{where}: keys {sorted(got)} != {sorted(want)}"]
        return [d for k in want for d in _differences(got[k], want[k], f"{where}/{k}")]
    if isinstance(want, list):
        if len(got) != len(want):
            return [f"{where}: {len(got)} items != {len(want)}"]
        return [d for i, (g, w) in enumerate(zip(got, want, strict=True))
                for d in _differences(g, w, f"{where}[{i}]")]
    return [] if got == want else [f"{where}: {got!r} != {want!r}"]


def _check(name: str, record: dict) -> None:
    golden = json.loads(GOLDEN.read_text()) if GOLDEN.is_file() else {}
    if RECORD:
        golden[name] = record
        GOLDEN.write_text(json.dumps(golden, indent=1, sort_keys=True) + "\n")
        return
    assert name in golden, f"no recorded output for {name}: record it (see module docstring)"
    want = golden[name]
    assert record["links_by_reason"] == want["links_by_reason"], name
    assert record["links_sha256"] == want["links_sha256"], f"{name}: links.csv moved"
    assert record.keys() == want.keys(), name
    if "report" in want:
        diffs = _differences(record["report"], want["report"])
        assert not diffs, f"{name}: report.json moved:\n" + "\n".join(diffs[:20])


@pytest.mark.parametrize("formation", ["a", "b", "c", "d"])
def test_formation_outputs_unchanged(formation, tmp_path):
    out = tmp_path / f"formation-{formation}"
    run_formation(FormationConfig(formation=formation, out=str(out), **SMALL))
    _check(f"run-formation-{formation}", _digest(out, tmp_path))


@pytest.mark.parametrize("formation", ["a", "b", "c", "d"])
def test_formation_paper_outputs_unchanged(formation, tmp_path):
    # the paper's Alg. 1 (and its keypoint merge radius), whatever the default
    out = tmp_path / f"formation-{formation}"
    run_formation(FormationConfig(formation=formation, out=str(out), resolution="paper", **SMALL))
    _check(f"run-formation-{formation}-paper", _digest(out, tmp_path))


@pytest.mark.parametrize("resolution", ["evidence", "paper"])
def test_resolve_output_unchanged(resolution, tmp_path):
    out = tmp_path / "formation-d"
    run_formation(FormationConfig(formation="d", out=str(out), fusion=False, resolution="paper",
                                  **SMALL))
    with open(out / "links.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    src = tmp_path / "in.csv"
    src.write_text("cam_i,feat_i,cam_j,feat_j\n" + "".join(
        f"{r['cam_i']},{r['feat_i']},{r['cam_j']},{r['feat_j']}\n" for r in rows))
    graph = tmp_path / "graph.csv"
    graph.write_text("".join(f"{i},{j}\n" for i in range(6) for j in range(i + 1, 6)))
    res = tmp_path / "resolved"
    res.mkdir()
    assert main(["resolve", "--links", str(src), "--comm-graph", str(graph),
                 "--out", str(res / "links.csv"), "--report", str(res / "report.json"),
                 "--resolution", resolution]) == 0
    suffix = "-paper" if resolution == "paper" else ""
    _check(f"resolve-formation-d-complete{suffix}", _digest(res, tmp_path))


@pytest.mark.parametrize("resolution", ["evidence", "paper"])
def test_run_images_outputs_unchanged(resolution, sceaux_small, tmp_path):
    out = tmp_path / "sceaux-ring2"
    assert main(["run-images", str(sceaux_small), "--graph", "ring2", "--max-size", "640",
                 "--no-rerun", "--out", str(out), "--resolution", resolution]) == 0
    suffix = "-paper" if resolution == "paper" else ""
    _check(f"run-images-sceaux4-ring2{suffix}", _digest(out, tmp_path, sceaux_small))


def test_comparison_is_exact_on_decisions_and_tolerant_on_reals():
    want = {"kept": 900, "cut": [1, 2], "rule": "evidence", "ok": True, "f1": 0.6834211593027969,
            "tiny": 2e-15}
    same_bits_elsewhere = dict(want, f1=0.6834211593027969 * (1 + 1e-12), tiny=-3e-15)
    assert _differences(same_bits_elsewhere, want) == []
    assert _differences(dict(want, kept=901), want) == ["report/kept: 901 != 900"]
    assert _differences(dict(want, cut=[1, 3]), want) == ["report/cut[1]: 3 != 2"]
    assert _differences(dict(want, cut=[1]), want) == ["report/cut: 1 items != 2"]
    assert _differences(dict(want, ok=False), want) == ["report/ok: False != True"]
    assert _differences(dict(want, kept=900.0), want)  # an int turned float is a change
    assert _differences(dict(want, f1=0.6844), want)  # one link of a thousand
    assert _differences({k: v for k, v in want.items() if k != "rule"}, want)


def test_guard_holds_on_another_cpu_kernel(tmp_path):
    """The guard must pass on a machine whose floating-point kernels differ from the one that
    recorded it. OpenBLAS's SandyBridge kernels (no FMA) stand in for such a machine: on them
    the earlier, byte-exact guard failed on formations c and d; the decisions do not move."""
    out = tmp_path / "formation-d"
    env = dict(os.environ, OPENBLAS_CORETYPE="SandyBridge")
    code = ("from pipeline.runs.formation import FormationConfig, run_formation; "
            f"run_formation(FormationConfig(formation='d', out={str(out)!r}, resolution='paper', "
            f"**{SMALL!r}))")
    subprocess.run([sys.executable, "-c", code], env=env, check=True, capture_output=True)
    _check("run-formation-d-paper", _digest(out, tmp_path))
