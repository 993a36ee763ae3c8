"""The ``cuts`` panel words the fusion stage's rule as it cuts (pipeline.fusion.landmarks,
"Outliers leave the landmark"): a link is cut when one of its ends is an outlier and the
other not; a link between two outliers is kept where they can be one point."""

import sys
from pathlib import Path

from viz.rerun_log import cut_summary

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_rerun_log import make_record  # noqa: E402


def test_the_cuts_panel_says_a_link_between_two_outliers_is_kept():
    text = cut_summary(make_record())
    line = next(x for x in text.splitlines() if "cut by fusion-outlier" in x)
    assert "an outlier and not the other" in line
    assert "a link between two outliers is kept where they can be one point" in line
