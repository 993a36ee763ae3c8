"""The fusion stage (Montijano et al., dynamic voting) after resolution on rendered formations.

    python bench/voting_pipeline.py

For each formation a–d and each local-estimate mode: links cut (good / spurious), fused
landmark error against ground truth and against pycolmap's robust triangulation of the same
tracks, rounds, messages and bytes. Writes ``runs/bench-voting/pipeline.json``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.errors import one_line_interrupts  # noqa: E402

one_line_interrupts(__name__, __file__)  # a Ctrl-C while the libraries below load

import numpy as np  # noqa: E402

from pipeline.errors import one_line_errors  # noqa: E402
from pipeline.outputs import results_folder_problem  # noqa: E402
from pipeline.runfolder import write_json_atomic  # noqa: E402

#: the repository's runs/, as every bench, whatever the current folder
OUT = ROOT / "runs" / "bench-voting"


def pipeline_fusion(formations=("a", "b", "c", "d"), seed: int = 0, size=(640, 480)) -> list:
    """Fusion after resolution on rendered formations, against ground truth and pycolmap.

    For each formation: render → SIFT → matching on comm edges → distributed resolution →
    :func:`pipeline.fusion.landmarks.fuse_tracks` with each local-estimate mode on the kept
    links; pycolmap's robust triangulation of the same tracks is the reference. A track's
    ground-truth point is the medoid of its observations' rendered 3D points.
    """
    import data_synth
    from pipeline.evaluation.links import link_truth
    from pipeline.evaluation.triangulation import medoid, triangulate_tracks
    from pipeline.fusion.landmarks import fuse_tracks
    from pipeline.progress import StageTimer
    from pipeline.stages import consistency_stage, extract_and_match

    rows = []
    for name in formations:
        f = data_synth.render(name, seed=seed, size=size)
        feats, _, links = extract_and_match(f.views, f.comm_edges, "sift", 2000,
                                            StageTimer(verbose=False))
        m = [len(x) for x in feats]
        res, _ = consistency_stage(m, f.comm_edges, links, resolution="paper")
        kept = links.subset(~np.asarray(res.deleted, dtype=bool))
        truth = link_truth(f, feats, kept)
        gt = [data_synth.points_from_keypoints(v, x.keypoints) for v, x in zip(f.views, feats,
                                                                              strict=True)]
        gt = [np.where(ok[:, None], P, np.nan) for P, ok in gt]
        all_gt = np.concatenate(gt)
        tri = triangulate_tracks(f.views, feats, kept, gt_points=gt)
        for local in ("robust", "pair", "neighbours"):
            t0 = time.perf_counter()
            fr = fuse_tracks(f.views, feats, kept, f.comm_edges, local=local)
            dt = time.perf_counter() - t0
            off = np.concatenate([[0], np.cumsum(m)])
            g = off[fr.obs_cam] + fr.obs_feat
            gt_pt = np.array([medoid(all_gt[g[fr.obs_track == t]]) for t in fr.track_ids])
            err = np.linalg.norm(fr.points - gt_pt, axis=1)
            col = tri.xyz[fr.track_ids]
            vs_colmap = np.linalg.norm(fr.points - col, axis=1)
            colmap_err = tri.gt_error[fr.track_ids]
            cut = fr.cut_links
            rows.append(dict(
                formation=name, local=local, links=len(kept), spurious=int((~truth).sum()),
                links_cut=int(cut.sum()), cut_spurious=int((cut & ~truth).sum()),
                cut_good=int((cut & truth).sum()), observations=fr.stats["observations"],
                observations_cut=fr.stats["observations_cut"], tracks=fr.stats["tracks"],
                tracks_fused=fr.stats["tracks_fused"],
                fused_err_median=float(np.nanmedian(err)), fused_err_p90=float(np.nanpercentile(err, 90)),
                colmap_err_median=float(np.nanmedian(colmap_err)),
                colmap_err_p90=float(np.nanpercentile(colmap_err, 90)),
                fused_vs_colmap_median=float(np.nanmedian(vs_colmap)),
                rounds=fr.stats["rounds"], messages=fr.stats["messages"], bytes=fr.stats["bytes"],
                seconds=dt))
    return rows


def print_pipeline(rows) -> None:
    print("\nFusion stage after resolution (640x480, seed 0; errors in scene units; GT = medoid "
          "of the observations' rendered points)")
    print(f"{'form':5s}{'local':11s}{'links':>6s}{'spur':>5s}{'cut':>5s}{'c.sp':>5s}{'c.gd':>5s}"
          f"{'obs cut':>8s}{'fused err med/p90':>19s}{'colmap err med/p90':>20s}"
          f"{'fused-colmap':>13s}{'rounds':>7s}{'msgs':>6s}{'MB':>7s}")
    for r in rows:
        print(f"{r['formation']:5s}{r['local']:11s}{r['links']:6d}{r['spurious']:5d}"
              f"{r['links_cut']:5d}{r['cut_spurious']:5d}{r['cut_good']:5d}{r['observations_cut']:8d}"
              f"{r['fused_err_median']:10.4f}/{r['fused_err_p90']:.4f}"
              f"{r['colmap_err_median']:11.4f}/{r['colmap_err_p90']:.4f}"
              f"{r['fused_vs_colmap_median']:13.4f}{r['rounds']:7d}{r['messages']:6d}"
              f"{r['bytes'] / 1e6:7.1f}")


@one_line_errors
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args(argv)
    if problem := results_folder_problem(args.out):
        ap.error(problem)
    prow = pipeline_fusion()
    print_pipeline(prow)
    write_json_atomic(args.out / "pipeline.json", dict(rows=prow))
    print(f"wrote {args.out / 'pipeline.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
