"""``resolve --report``'s ``deleted_by_case`` names the cases of the rule that ran: under a
fault flag the default ``sync`` gives way to Alg. 1, whose cases (b) and (c) are the ones
to count, not a ``sync`` entry of a rule that never ran."""

import json

from pipeline.__main__ import main
from pipeline.consistency.rules import deleted_cases

FIG1 = "cam_i,feat_i,cam_j,feat_j\n0,0,3,1\n0,0,1,0\n1,0,2,0\n3,0,2,0\n"


def test_the_cases_are_those_of_the_rule_that_ran(tmp_path):
    src, out, rep = tmp_path / "in.csv", tmp_path / "out.csv", tmp_path / "r.json"
    src.write_text(FIG1)
    assert main(["resolve", "--links", str(src), "--out", str(out), "--report", str(rep),
                 "--delay-rounds", "1"]) == 0
    s = json.loads(rep.read_text())
    assert s["resolution_method"] == "paper"
    assert tuple(s["deleted_by_case"]) == deleted_cases("paper")
    assert sum(s["deleted_by_case"].values()) == s["deleted"] == 1
