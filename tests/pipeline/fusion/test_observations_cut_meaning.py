"""What fusion's ``observations_cut`` counts: the observations declared outliers (a link
between two outliers stays where they can be one point, so an outlier may keep links), and
the docs say so rather than "observations whose links were cut"."""

import re
from pathlib import Path

import numpy as np
from test_landmarks import planted_rig

from pipeline.fusion.landmarks import FusionResult, fuse_tracks

ROOT = Path(__file__).resolve().parents[3]


def test_observations_cut_counts_the_observations_declared_outliers():
    views, feats, links, edges, _ = planted_rig()
    res = fuse_tracks(views, feats, links, edges, sigma_px=0.5)
    assert res.stats["observations_cut"] == int((~res.obs_inlier).sum()) == 1
    assert res.stats["links_cut"] == int(np.count_nonzero(res.cut_links))


def test_the_docs_describe_observations_cut_as_outliers():
    doc = " ".join(FusionResult.__doc__.split())
    assert re.search(r"``observations_cut`` \(observations \*declared outliers\*", doc)
    readme = " ".join((ROOT / "README.md").read_text().split())
    assert "`observations_cut` counts the observations declared outliers" in readme
