"""Conflicts before and after the distributed stage on a rendered formation (paper Sec. V-B)."""

import numpy as np

from pipeline.association import AssociationGraph, count_conflicts
from pipeline.consistency import resolve_conflicts
from pipeline.consistency.centralized import union_find_conflicts
from pipeline.types import Links


def test_rendered_formation_d_conflicts_cut_to_zero():
    import data_synth
    from pipeline.matching.features import extract_all
    from pipeline.matching.pairs import match_edges

    f = data_synth.render("d", seed=0, size=(320, 240))
    feats = extract_all(f.views)
    m = [len(x) for x in feats]
    links = Links.from_matches(match_edges(feats, f.views, f.comm_edges))
    before = count_conflicts(AssociationGraph(m, links))
    assert before.conflictive_sets > 0  # real matching on cycles does create conflicts

    res = resolve_conflicts(m, f.comm_edges, links, resolution="paper")
    after = count_conflicts(AssociationGraph(m, res.kept()))
    assert after.conflictive_sets == 0 and after.conflictive_features == 0
    # cuts are few and only inside the conflictive sets found before
    _, conflictive = union_find_conflicts(m, links)
    off = np.concatenate([[0], np.cumsum(m)])
    assert conflictive[off[links.cam_i[res.deleted]] + links.feat_i[res.deleted]].all()
    assert 0 < res.deleted.sum() <= before.conflictive_features
    assert res.stats["asymmetric_links"] == 0
    # Prop. 4.2 / Cor. 4.4: the sets are split, not dissolved: association sets grow
    assert after.association_sets >= before.association_sets
