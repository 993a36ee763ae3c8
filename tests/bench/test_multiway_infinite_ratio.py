"""bench/multiway.py's resolve:RULE rows write the links to a CSV that resolve reads: a link of
Lowe ratio inf (quality -inf, a Hungarian pair whose end sits at descriptor distance 0 from
another landmark) made resolve refuse the file ('quality '-inf' is not a finite number'). It is
written below every finite quality, so resolve keeps the pipeline's decisions."""
import numpy as np
import pytest
from benchload import load_bench

from pipeline.consistency import resolve_conflicts
from pipeline.types import Links


def test_a_quality_of_minus_inf_is_written_below_every_other():
    bench = load_bench("multiway")
    q = np.array([0.9, -np.inf, -4.5, 1.0, -np.inf])
    written = bench.quality_as_written(q)
    assert np.isfinite(written).all() and np.array_equal(written[[0, 2, 3]], q[[0, 2, 3]])
    assert written[1] == written[4] == pytest.approx(-5.5, abs=1e-12)
    assert np.array_equal(np.argsort(written, kind="stable"), np.argsort(q, kind="stable"))


@pytest.mark.parametrize("rule", ["sync", "evidence"])
def test_resolve_rows_read_a_link_of_ratio_inf_and_cut_as_the_pipeline(rule):
    bench = load_bench("multiway")
    # a cycle 0:0 - 1:0 - 2:0 - 0:1 (0:0 and 0:1 in one set) and a clean track on feature 2
    links = Links([0, 1, 0, 0, 0, 1], [0, 0, 1, 2, 2, 2], [1, 2, 2, 1, 2, 2],
                  [0, 0, 0, 2, 2, 2], np.array([0.9, 0.8, -np.inf, 0.7, 0.6, 0.5]))
    m = np.array([3, 3, 3])
    edges = np.array([[0, 1], [0, 2], [1, 2]])
    kept = bench.run_resolve_cli(rule, m, edges, links, cap_gb=2.0)["kept"]
    in_pipeline = ~resolve_conflicts(m, edges, links, resolution=rule).deleted
    assert kept.tolist() == in_pipeline.tolist() == [True, True, False, True, True, True]
