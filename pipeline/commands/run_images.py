"""``python -m pipeline run-images DIR --graph KIND``: the whole pipeline on real photographs.

The options of the run; the run itself is :func:`pipeline.images.run_images`.
"""

from __future__ import annotations

import argparse

from pipeline.commands.options import add_feature_options, feature_options
from pipeline.errors import InputError
from pipeline.images import ImagesConfig

__all__ = ["add_arguments", "config_from_args", "run"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("directory", metavar="DIR",
                   help="folder of photographs (JPEG/PNG/TIFF; taken in name order)")
    p.add_argument("--graph", required=True, metavar="ring|ring2|complete|knn:K|seq:K|FILE",
                   help="communication graph: ring, ring2 (ring + 2-hop chords), complete, "
                        "knn:K (each image with the K images most similar to it, by a global "
                        "descriptor of its features: for unordered photos), seq:K (each image "
                        "with the K nearest in name order: for ordered sequences), or a file of "
                        "'cam_i,cam_j' lines (0-based indices in name order, or image names)")
    p.add_argument("--intrinsics", default="auto", metavar="auto|exif|K.txt",
                   help="auto (DIR/K.txt, else EXIF, else a guessed focal length), exif, or "
                        "a K.txt at the images' full resolution (default auto)")
    p.add_argument("--max-size", type=int, default=1600, metavar="PX",
                   help="longest image side after downscaling (default 1600; 0 = full size)")
    add_feature_options(p, photos=True)
    p.add_argument("--export-db", action="store_true",
                   help="also write the matches as a COLMAP database (run folder/database.db): "
                        "matches table = every link, two-view geometries = kept links")
    p.add_argument("--no-fusion", action="store_true", help="skip the fusion stage")
    p.add_argument("--no-rerun", action="store_true", help="do not write recording.rrd")
    live = p.add_mutually_exclusive_group()
    live.add_argument("--spawn", action="store_true",
                      help="also show the recording in a new Rerun viewer (needs a display)")
    live.add_argument("--connect", nargs="?", const="connect", default=None, metavar="URL",
                      help="also stream the recording to a running Rerun viewer (default URL: "
                           "Rerun's, rerun+http://127.0.0.1:9876/proxy)")
    p.add_argument("--threads", type=int, default=1,
                   help="threads of COLMAP's mapper (default 1: repeatable figures; -1: all cores)")
    p.add_argument("--out", default=None,
                   help="run folder (default runs/images-<DIR name>-<graph>)")


def config_from_args(args) -> ImagesConfig:
    if args.max_size < 0:
        raise InputError(f"--max-size {args.max_size}: expected a positive number of pixels, "
                         f"or 0 for full resolution")
    method, max_features = feature_options(args)
    return ImagesConfig(directory=args.directory, graph=args.graph, intrinsics=args.intrinsics,
                        max_size=args.max_size or None, features=method,
                        max_features=max_features, fusion=not args.no_fusion,
                        rerun=not args.no_rerun, export_db=args.export_db, out=args.out,
                        threads=args.threads, live="spawn" if args.spawn else args.connect)


def run(args) -> int:
    from pipeline.images import run_images

    out = run_images(config_from_args(args))
    written = ["report.json", "links.csv", "sparse/"]
    written += [] if args.no_rerun else ["recording.rrd"]
    written += ["database.db"] if args.export_db else []
    print(f"run written to {out}/ ({', '.join(written)})")
    return 0
