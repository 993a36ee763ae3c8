"""The pair view of two images of very different shapes (viz.rerun_log): a 2000 x 60 image
beside a 60 x 2000 one made a 66667 x 2000 canvas, which JPEG cannot encode (65500 px at
most): OpenCV printed an encoder error and the canvas was stored raw, 400 MB in the
recording (2.3 GB of memory, run-images on two such photographs)."""

import cv2
import numpy as np
from rerun.chunk import RrdReader
from test_rerun_log import make_record

from viz.rerun_log import log_run


def _pair_canvas(path):
    for chunk in RrdReader(path).store().stream().to_chunks():
        if not chunk.entity_path.startswith("/matches/") or chunk.entity_path.count("/") != 2:
            continue
        batch = chunk.to_record_batch()
        blob = [c for c in batch.schema.names if c.endswith("EncodedImage:blob")]
        if blob:
            data = np.asarray(batch.column(blob[0]).to_pylist()[-1][0], dtype=np.uint8)
            return cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    raise AssertionError("no JPEG pair canvas in the recording")


def test_a_wide_and_a_tall_image_make_a_bounded_jpeg_canvas(tmp_path):
    record = make_record(n_cams=2, size=(2000, 60))
    rng = np.random.default_rng(0)
    record.views[1].image = rng.integers(0, 255, size=(2000, 60, 3), dtype=np.uint8)
    path = log_run(tmp_path / "recording.rrd", record)
    canvas = _pair_canvas(path)
    assert canvas.shape[1] <= 2 * 2000 and canvas.shape[0] >= 1
    assert path.stat().st_size < 5 * 2**20


def test_a_pair_of_one_size_is_not_scaled(tmp_path):
    record = make_record(n_cams=2, size=(64, 48))
    canvas = _pair_canvas(log_run(tmp_path / "recording.rrd", record))
    assert canvas.shape[:2] == (48, 128)
