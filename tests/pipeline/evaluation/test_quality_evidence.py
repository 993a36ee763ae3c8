"""The links' quality against their own cycles: informative, reversed, constant."""

import json

import numpy as np
import pytest

from pipeline.evaluation.quality import quality_evidence
from pipeline.types import Links


def _ring2(seed: int, n: int = 40, k: int = 10, p_swap: float = 0.4):
    """``n`` cameras on a ring2 graph, ``k`` landmarks each; a share of the pairs swap two
    matches. Returns features per camera, links and which links are right."""
    rng = np.random.default_rng(seed)
    perm = [rng.permutation(k) for _ in range(n)]
    inv = [np.argsort(p) for p in perm]
    rows, good = [], []
    for i in range(n):
        for d in (1, 2):
            j = (i + d) % n
            tgt = np.arange(k)
            if rng.random() < p_swap:
                a, b = rng.choice(k, 2, replace=False)
                tgt[a], tgt[b] = tgt[b], tgt[a]
            for lm in range(k):
                rows.append((i, int(inv[i][lm]), j, int(inv[j][tgt[lm]])))
                good.append(tgt[lm] == lm)
    ci, fi, cj, fj = (np.array(c) for c in zip(*rows, strict=True))
    return np.full(n, k), ci, fi, cj, fj, np.array(good)


def test_a_quality_that_tracks_the_truth_is_higher_on_confirmed_links_and_its_reverse_lower():
    m, ci, fi, cj, fj, good = _ring2(0)
    rng = np.random.default_rng(1)
    q = np.where(good, rng.uniform(0.4, 0.9, good.size), rng.uniform(0.1, 0.6, good.size))
    ok = quality_evidence(m, Links(ci, fi, cj, fj, q))
    rev = quality_evidence(m, Links(ci, fi, cj, fj, 1.0 - q))
    assert ok["confirmed"] > 0 and ok["refuted"] > 0 and not ok["constant"]
    assert ok["auc"] > 0.6 and ok["p_higher"] < 1e-3 and ok["p_reversed"] > 0.5
    assert rev["auc"] == pytest.approx(1.0 - ok["auc"], abs=1e-12)
    assert rev["p_reversed"] == pytest.approx(ok["p_higher"], rel=1e-9)
    assert (rev["confirmed"], rev["refuted"]) == (ok["confirmed"], ok["refuted"])


def test_a_constant_quality_or_no_link_is_not_tested():
    m, ci, fi, cj, fj, _ = _ring2(2)
    c = quality_evidence(m, Links(ci, fi, cj, fj, np.full(ci.size, 0.5)))
    assert c["constant"] and "auc" not in c and c["confirmed"] > 0
    empty = quality_evidence([3, 3], Links([], [], [], []))
    assert empty == {"checked": 0, "confirmed": 0, "refuted": 0, "constant": True,
                     "above_one": 0}


def _resolve_report(tmp_path, quality_of, *flags) -> tuple[dict, np.ndarray]:
    """``resolve --report`` on the ring2 links of ``_ring2(3)`` with ``quality_of(good)`` as
    their quality: the report and the qualities written."""
    from pipeline.__main__ import main

    m, ci, fi, cj, fj, good = _ring2(3)
    q = quality_of(good)
    src = tmp_path / "links.csv"
    src.write_text("".join(f"{a},{b},{c},{d},{e:.6f}\n"
                           for a, b, c, d, e in zip(ci, fi, cj, fj, q, strict=True)))
    rep = tmp_path / "rep.json"
    assert main(["resolve", "--links", str(src), "--out", str(tmp_path / "o.csv"),
                 "--report", str(rep), "-q", *flags]) == 0
    return json.loads(rep.read_text()), q


def _informative(good, scale=1.0):
    rng = np.random.default_rng(4)
    return scale * np.where(good, rng.uniform(0.4, 0.9, good.size),
                            rng.uniform(0.1, 0.6, good.size))


@pytest.mark.parametrize("reverse", [False, True])
def test_resolve_warns_of_a_reversed_quality_only(tmp_path, capsys, reverse):
    report, _ = _resolve_report(
        tmp_path, lambda g: 1.0 - _informative(g) if reverse else _informative(g))
    codes = [w["code"] for w in report.get("warnings", [])]
    assert ("quality-reversed" in codes) == reverse
    assert (report["quality_evidence"]["auc"] < 0.5) == reverse
    assert ("looks reversed" in capsys.readouterr().err) == reverse


def test_a_large_input_is_checked_on_a_fixed_draw_of_its_links():
    m, ci, fi, cj, fj, good = _ring2(5)
    q = np.where(good, 0.8, 0.3)
    links = Links(ci, fi, cj, fj, q)
    whole = quality_evidence(m, links)
    assert whole["checked"] == len(links)
    few = quality_evidence(m, links, max_checked=200)
    assert few["checked"] == 200 and few == quality_evidence(m, links, max_checked=200)
    # the entries' budget (each link costs its ends' degrees, 4 + 4 on a ring2) bounds it too
    assert quality_evidence(m, links, max_entries=8 * 50)["checked"] == 50
    assert few["confirmed"] + few["refuted"] <= 200 and few["p_higher"] < 1e-3


def test_links_out_of_range_and_negative_caps_are_refused():
    """Feature ids past their camera's count were read as the next camera's features and
    judged ('confirmed': 3 on the paper's Fig. 1 with camera 0 given 1 feature); a negative
    max_checked checked L - 1 links."""
    from pipeline.errors import InputError

    fig1 = Links([0, 1, 2, 0], [0, 0, 0, 1], [1, 2, 3, 3], [0, 0, 0, 0])
    with pytest.raises(InputError, match=r"link 3 \(0,1\)-\(3,0\): feature id out of range"):
        quality_evidence([1, 1, 1, 1], fig1)
    assert quality_evidence([2, 1, 1, 1], fig1)["checked"] == 4
    for kw in (dict(max_checked=-1), dict(max_entries=-5), dict(max_checked=2.5)):
        with pytest.raises(InputError, match=f"{next(iter(kw))} .*>= 0"):
            quality_evidence([2, 1, 1, 1], fig1, **kw)
    with pytest.raises(InputError, match=r"link 0 \(0,0\)-\(4,0\): camera id out of range 0..3"):
        quality_evidence([2, 1, 1, 1], Links([0], [0], [4], [0]))


@pytest.mark.parametrize("rule, reads", [("sync", True), ("paper", False)])
def test_the_reversed_warning_says_when_the_rule_that_ran_ignores_the_quality(tmp_path, rule,
                                                                              reads):
    # a distance given for a similarity
    report, _ = _resolve_report(tmp_path, lambda g: np.where(g, 0.2, 0.8), "--resolution", rule)
    assert report["quality_evidence"]["read_by_rule"] is reads
    (w,) = [w for w in report["warnings"] if w["code"] == "quality-reversed"]
    assert ("does not read the quality" in w["message"]) is not reads
    assert f"the rule that ran, {rule}," in w["message"] or reads


@pytest.mark.parametrize("scale, warned", [(1.0, False), (100.0, True)])
def test_a_quality_on_another_scale_than_one_minus_the_ratio_is_warned(tmp_path, capsys, scale,
                                                                      warned):
    report, q = _resolve_report(tmp_path, lambda g: _informative(g, scale))
    assert report["quality_evidence"]["above_one"] == (int((q > 1).sum()) if warned else 0)
    codes = [w["code"] for w in report.get("warnings", [])]
    assert ("quality-scale" in codes) is warned
    assert ("rescale the quality to [0, 1]" in capsys.readouterr().err) is warned
