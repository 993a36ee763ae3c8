"""End to end: a small rendered formation through every stage, then the run folder is checked
against itself (report vs links.csv vs sparse/ vs recording.rrd)."""

import csv
import json

import numpy as np
import pycolmap
import pytest

from pipeline.association import AssociationGraph, count_conflicts
from pipeline.runs.formation import FormationConfig, run_formation
from pipeline.types import Links

SMALL = dict(formation="d", seed=0, size=(320, 240), max_features=600)


@pytest.fixture(scope="module")
def small_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("runs") / "formation-d"
    run_formation(FormationConfig(**SMALL, out=str(out)))
    report = json.loads((out / "report.json").read_text())
    with open(out / "links.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    return out, report, rows


def test_outputs_exist(small_run):
    out, _, _ = small_run
    for name in ("report.json", "links.csv", "sparse", "recording.rrd"):
        assert (out / name).exists(), name


def test_conflicts_found_and_resolved(small_run):
    _, report, _ = small_run
    assert report["before"]["conflictive_sets"] > 0
    assert report["after"]["conflictive_sets"] == 0
    r = report["resolution"]
    assert r["deleted_links"] == r["good_deleted"] + r["spurious_deleted"]
    assert sum(r["deleted_by_case"].values()) == r["deleted_links"]


def test_resolution_quality_recounts_from_links_csv(small_run):
    _, report, rows = small_run
    q = report["resolution_quality"]
    assert report["resolution"]["method"] == "evidence"
    assert list(q) == ["paper", "evidence", "sync", "paper-labels", "drop_conflictive_sets",
                       "keep_first_per_image", "quality_merge", "spectral_sync", "clear", "oracle"]
    assert q["paper-labels"] == q["paper"]  # the same cuts (rules.py, cuts_as)
    # the run's own method: what its consistency stage cut, read back from links.csv
    cut = [r for r in rows if r["reason"] == "resolution"]
    assert q["evidence"]["good_cut"] == sum(r["truth"] == "1" for r in cut)
    assert q["evidence"]["spurious_cut"] == sum(r["truth"] == "0" for r in cut)
    spurious_in = q["oracle"]["spurious_in_sets"]
    assert spurious_in > 0 and q["oracle"]["spurious_left"] == 0
    for name, s in q.items():
        assert s["spurious_in_sets"] == spurious_in, name
        assert 0 <= s["spurious_left"] <= spurious_in <= s["spurious_left"] + s["spurious_cut"]
        # nobody cuts fewer good links than the oracle while leaving no spurious link
        assert s["good_cut"] >= q["oracle"]["good_cut"] or s["spurious_left"] > 0, name
    assert q["evidence"]["pairwise_f1"] == report["pairwise"]["after_resolution"]["f1"]


def test_report_equals_recount_from_links_csv(small_run):
    _, report, rows = small_run
    assert list(rows[0]) == ["cam_i", "feat_i", "cam_j", "feat_j", "status", "reason", "round",
                             "truth"]
    kept = [r for r in rows if r["status"] == "kept"]
    cut = [r for r in rows if r["reason"] == "resolution"]
    assert report["before"]["links"] == len(rows)
    assert report["after"]["links"] == len(kept)
    assert report["resolution"]["deleted_links"] == len(cut)
    assert report["resolution"]["good_deleted"] == sum(r["truth"] == "1" for r in cut)
    assert report["before"]["good_links"] == sum(r["truth"] == "1" for r in rows)
    assert report["after"]["spurious_links"] == sum(r["truth"] == "0" for r in kept)
    assert all(r["reason"] == "" for r in kept)
    assert all(r["reason"] in ("resolution", "fusion-outlier") for r in rows
               if r["status"] == "deleted")

    def links_of(rs):
        return Links(*[np.array([int(r[k]) for r in rs], dtype=np.int64)
                       for k in ("cam_i", "feat_i", "cam_j", "feat_j")])

    m = report["features_per_camera"]
    for section, rs in (("before", rows), ("after", kept)):
        c = count_conflicts(AssociationGraph(m, links_of(rs))).as_dict()
        for key, value in c.items():
            assert report[section][key] == value, (section, key)


def test_sparse_model_loads(small_run):
    out, report, _ = small_run
    rec = pycolmap.Reconstruction(str(out / "sparse"))
    assert rec.num_images() == report["n_cameras"]
    assert rec.num_points3D() > 0
    assert rec.num_points3D() <= report["triangulation"]["after"]["triangulated_tracks"]


def test_recording_holds_kept_and_deleted_links(small_run):
    from viz.recording_reader import count_strips

    out, report, rows = small_run
    deleted = sum(r["status"] == "deleted" for r in rows)
    assert count_strips(out / "recording.rrd", "world/links/deleted") == deleted
    assert count_strips(out / "recording.rrd", "world/links/kept") == len(rows) - deleted


def test_failed_run_keeps_previous_run(small_run, monkeypatch):
    import pipeline.evaluation.triangulation as tri

    out, report, _ = small_run
    before = (out / "report.json").read_bytes()

    def broken(*args, **kwargs):
        raise RuntimeError("triangulation failed")

    monkeypatch.setattr(tri, "triangulate_tracks", broken)
    with pytest.raises(RuntimeError, match="triangulation failed"):
        run_formation(FormationConfig(**SMALL, out=str(out), rerun=False))
    assert (out / "report.json").read_bytes() == before
    assert sorted(p.name for p in out.parent.iterdir()) == [out.name]


def test_steps_over_a_transport_without_online_fusion_need_no_fusion(tmp_path, capsys):
    """``--steps`` over a transport whose module has no ``online_fusion`` job: one line
    naming the transport and ``--no-fusion``, exit 2, nothing written."""
    import types

    from pipeline.__main__ import main
    from pipeline.runs.transports import TransportEntry, register, unregister

    register(TransportEntry("nofusion", "a transport without online fusion",
                            lambda: types.SimpleNamespace(online_stage=None)))
    try:
        assert main(["run-formation", "--steps", "2", "--transport", "nofusion", "--out",
                     str(tmp_path / "x")]) == 2
    finally:
        unregister("nofusion")
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "--transport nofusion" in err and "add --no-fusion" in err
    assert not (tmp_path / "x").exists()


def test_resolution_quality_of_a_faulty_run_names_the_rule_that_ran(small_run, tmp_path):
    """On a faulty network the evidence rule gives way to Alg. 1: the run's cuts are the row
    of ``paper``; the ``evidence`` row is the evidence rule on the same links, fault-free."""
    from pipeline.faults import FaultConfig

    _, fault_free, _ = small_run
    out = tmp_path / "faulty"
    # a crash the run never reaches: the network is faulty, the links the same
    run_formation(FormationConfig(**SMALL, out=str(out), fusion=False, rerun=False,
                                  faults=FaultConfig(crash=((5, 100_000),))))
    report = json.loads((out / "report.json").read_text())
    with open(out / "links.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert report["resolution"]["method"] == "paper" and report["before"] == fault_free["before"]
    q, q0 = report["resolution_quality"], fault_free["resolution_quality"]
    cut = [r for r in rows if r["reason"] == "resolution"]
    assert q["paper"]["good_cut"] == sum(r["truth"] == "1" for r in cut)
    assert q["paper"]["spurious_cut"] == sum(r["truth"] == "0" for r in cut)
    assert q["paper"]["pairwise_f1"] == report["pairwise"]["after_resolution"]["f1"]
    assert q["evidence"] == q0["evidence"]
