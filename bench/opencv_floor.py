"""The OpenCV-only floor of the default run: what matching the same images costs without the
pipeline around it.

Reads the images of a folder (``cam00.png`` …) and their intrinsics ``K.txt`` (3x3, shared),
extracts SIFT (at most 2000 features per image), and on every pair of cameras (the complete
graph: formation d) matches by kNN (k = 2) with Lowe's ratio test (0.8) and fits an essential
matrix with ``cv2.USAC_MAGSAC`` (1 px, confidence 0.999, 1000 iterations) — the calls of the
default run's features and matching stages, and nothing else: no duplicate merging, no mutual
check, no consistency, fusion, triangulation, evaluation or output. Prints one line of JSON
with its wall time and its inlier count.

Run by ``bench/run_formation.py`` in a subprocess of its own (imports count, as they do for
the run it is compared with, and, like the run, it ends without the interpreter's
teardown)::

    python bench/opencv_floor.py IMAGE_DIR
"""

import time

T0 = time.perf_counter()

import json  # noqa: E402
import os  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.errors import one_line_interrupts  # noqa: E402  (it loads no library)

one_line_interrupts(__name__, __file__)  # a Ctrl-C while the libraries below load

import cv2  # noqa: E402
import numpy as np  # noqa: E402


def main(folder: Path) -> dict:
    paths = sorted(folder.glob("cam*.png"))
    K = np.loadtxt(folder / "K.txt").reshape(3, 3)
    f_mean = (K[0, 0] + K[1, 1]) / 2
    sift = cv2.SIFT_create(nfeatures=2000)
    feats = []
    for p in paths:
        kps, desc = sift.detectAndCompute(cv2.imread(str(p), cv2.IMREAD_GRAYSCALE), None)
        xy = cv2.KeyPoint_convert(kps).reshape(-1, 1, 2).astype(np.float64)
        feats.append((cv2.undistortPoints(xy, K, None), desc))
    matcher = cv2.BFMatcher(cv2.NORM_L2)
    inliers = 0
    for i in range(len(feats)):
        for j in range(i + 1, len(feats)):
            (x_i, d_i), (x_j, d_j) = feats[i], feats[j]
            good = [m[0] for m in matcher.knnMatch(d_i, d_j, k=2)
                    if len(m) == 2 and m[0].distance < 0.8 * m[1].distance]
            if len(good) < 8:
                continue
            a = x_i[[m.queryIdx for m in good]]
            b = x_j[[m.trainIdx for m in good]]
            E, mask = cv2.findEssentialMat(a, b, np.eye(3), cv2.USAC_MAGSAC, 0.999,
                                           1.0 / f_mean, 1000)
            inliers += int(mask.sum()) if mask is not None else 0
    return {"images": len(paths), "edges": len(paths) * (len(paths) - 1) // 2,
            "inliers": inliers, "wall_s": time.perf_counter() - T0}


USAGE = "usage: python bench/opencv_floor.py IMAGE_DIR  (cam*.png and K.txt; -h: what it measures)"


def cli(argv: list[str]) -> int:
    """The command line by hand, not argparse: its import would count in the floor's time."""
    if argv and argv[0] in ("-h", "--help"):
        print(f"{USAGE}\n\n{__doc__}")
        return 0
    if len(argv) != 1:
        print(f"{USAGE}\nerror: expected one IMAGE_DIR, got {len(argv)} arguments "
              "(bench/run_formation.py renders the images and runs this floor on them)",
              file=sys.stderr)
        return 2
    folder = Path(argv[0])
    if not (folder / "K.txt").is_file() or not any(folder.glob("cam*.png")):
        print(f"error: {argv[0]}: no cam*.png images with their K.txt; give the folder of a "
              "rendered formation (bench/run_formation.py writes one)", file=sys.stderr)
        return 2
    print(json.dumps(main(folder)), flush=True)
    return 0


if __name__ == "__main__":
    if cli(sys.argv[1:]):
        sys.exit(2)
    # the run it is compared with ends without the interpreter's teardown
    # (pipeline.__main__.entry); so does the floor, to compare the same work
    os._exit(0)
