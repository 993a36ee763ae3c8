"""The record of an online step whose small conflictive set is solved at its root
(``gather``, pipeline.consistency.engines.online_weigh), by the simulator or by the stage's
robots (``robots_solve``), counts that set as the rule's flood
counts it: its conflictive features, the set and the rule's cut."""

import pytest

from pipeline.consistency.engines.online import Frame, OnlineAssociation
from pipeline.types import Links


@pytest.mark.parametrize("gather,robots_solve", [(True, False), (True, True), (False, False)])
def test_a_gathered_conflictive_set_is_counted_as_the_rules(gather, robots_solve):
    """Image 0's two features are chained through images 1 and 2: one conflictive set of
    four features, solved by cutting the weakest link (1-2); two features in conflict. The
    same figures whether the simulator or the stage's robots solve the set at its root."""
    oa = OnlineAssociation(window=2, gather=gather, robots_solve=robots_solve)
    rec = oa.add_step([Frame(0, 2), Frame(1, 1), Frame(2, 1)],
                      Links([0, 0, 1], [0, 1, 0], [1, 2, 2], [0, 0, 0], [0.9, 0.8, 0.3]))
    assert oa.links.kept.tolist() == [True, True, False]
    assert (rec["conflictive_features"], rec["conflictive_sets"], rec["cut_rule"]) == (2, 1, 1)
    assert (rec["weighed_sets"], rec["cut_weigh"]) == (0, 0)
