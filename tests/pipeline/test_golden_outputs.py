"""Regression guard: the run outputs of formations a–d, ``resolve`` and ``run-images`` on
Sceaux are byte-identical to the recorded ones.

A change that is meant to alter results (a new default, a better stage) re-records them with
``FORMATION_MATCH_RECORD_GOLDEN=1 pytest tests/pipeline/test_golden_outputs.py`` and says in
its commit message which figures moved and why. Every other change must leave them alone.

Each record is the SHA-256 of ``links.csv`` and of ``report.json`` without the parts that
legitimately differ between runs (``timings_s``, ``versions``, the output path in
``config``, and temporary paths), plus the per-reason link counts, so a failure shows what moved.
"""

from __future__ import annotations

import csv
import hashlib
import json
import os
from collections import Counter
from pathlib import Path

import pytest

from pipeline.__main__ import main
from pipeline.run import FormationConfig, run_formation

GOLDEN = Path(__file__).resolve().parents[1] / "data" / "golden_outputs.json"
RECORD = os.environ.get("FORMATION_MATCH_RECORD_GOLDEN") == "1"
SMALL = dict(seed=0, size=(320, 240), max_features=600, rerun=False)


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
        record["report_sha256"] = hashlib.sha256(canonical.encode()).hexdigest()
    return record


def _check(name: str, record: dict) -> None:
    golden = json.loads(GOLDEN.read_text()) if GOLDEN.is_file() else {}
    if RECORD:
        golden[name] = record
        GOLDEN.write_text(json.dumps(golden, indent=1, sort_keys=True) + "\n")
        return
    assert name in golden, f"no recorded output for {name}: record it (see module docstring)"
    assert record["links_by_reason"] == golden[name]["links_by_reason"], name
    assert record == golden[name], name


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
