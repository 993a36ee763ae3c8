"""``python -m pipeline resolve``: round trip on the paper's Fig. 1 and each bad input."""

import json
import re

import numpy as np
import pytest

from pipeline.__main__ import main
from pipeline.association import AssociationGraph, count_conflicts
from pipeline.inputs.linkscsv import features_per_camera_for, read_run_links_csv

FIG1 = "cam_i,feat_i,cam_j,feat_j\n0,0,3,1\n0,0,1,0\n1,0,2,0\n3,0,2,0\n"


def test_round_trip_fig1(tmp_path, capsys):
    src = tmp_path / "in.csv"
    src.write_text(FIG1)
    out = tmp_path / "out.csv"
    assert main(["resolve", "--links", str(src), "--out", str(out), "--resolution", "paper",
                 "--report", str(tmp_path / "r.json")]) == 0
    printed = capsys.readouterr().out
    assert "conflictive sets: 1 before, 0 after" in printed and "deleted: 1 links" in printed
    back = read_run_links_csv(out)
    # every input row once, in input order (the 4th row normalised to cam_i < cam_j)
    assert back.links.cam_i.tolist() == [0, 0, 1, 2]
    assert back.status.tolist() == ["kept", "deleted", "kept", "kept"]
    assert back.reason.tolist() == ["", "resolution", "", ""]
    assert back.round[1] >= 1 and (back.truth == -1).all()
    kept = back.links.subset(back.status == "kept")
    m = features_per_camera_for(back.links)
    assert count_conflicts(AssociationGraph(m, kept)).conflictive_sets == 0
    assert (tmp_path / "r.json").is_file()
    assert src.read_text() == FIG1  # input untouched


def test_evidence_cuts_the_weakest_link_of_the_cycle(tmp_path, capsys):
    # Fig. 1 with a quality column: the link (1,0)-(2,0) has the worst Lowe ratio (0.9);
    # Alg. 1 cuts (0,0)-(1,0) where its waves meet, the evidence rule the weak link
    src = tmp_path / "in.csv"
    src.write_text("cam_i,feat_i,cam_j,feat_j,quality\n0,0,3,1,0.8\n0,0,1,0,0.8\n"
                   "1,0,2,0,0.1\n3,0,2,0,0.8\n")
    out = tmp_path / "out.csv"
    assert main(["resolve", "--links", str(src), "--out", str(out), "--resolution",
                 "evidence"]) == 0
    assert "deleted: 1 links by the evidence rule" in capsys.readouterr().out
    back = read_run_links_csv(out)
    assert back.status.tolist() == ["kept", "kept", "deleted", "kept"]
    assert back.reason.tolist() == ["", "", "resolution", ""]


def test_baselines_beside_the_rule(tmp_path, capsys):
    """--baselines: every centralized baseline on the same links, each with what it deleted
    and how many links it decided otherwise than the rule (counted here from its own mask)."""
    import json

    from pipeline.consistency.centralized import BASELINES
    from pipeline.inputs.linkscsv import read_links_csv

    src = tmp_path / "in.csv"
    src.write_text("cam_i,feat_i,cam_j,feat_j,quality\n0,0,3,1,0.8\n0,0,1,0,0.8\n"
                   "1,0,2,0,0.1\n3,0,2,0,0.8\n")
    out, rep = tmp_path / "out.csv", tmp_path / "r.json"
    assert main(["resolve", "--links", str(src), "--out", str(out), "--resolution", "evidence",
                 "--baselines", "--report", str(rep)]) == 0
    captured = capsys.readouterr()
    printed = captured.out
    assert "[baselines] the centralized baselines beside the rule, on 5 features" in captured.err
    summary = json.loads(rep.read_text())
    assert sorted(summary["baselines"]) == sorted(BASELINES)
    kept = read_run_links_csv(out).status == "kept"
    links = read_links_csv(src).links
    m = features_per_camera_for(links)
    for name, fn in BASELINES.items():
        mask = np.asarray(fn(m, links), dtype=bool)
        row = summary["baselines"][name]
        assert row["deleted_links"] == int((~mask).sum()), name
        assert row["decided_otherwise"] == int((mask != kept).sum()), name
        assert row["conflictive_sets"] == count_conflicts(
            AssociationGraph(m, links.subset(mask))).conflictive_sets, name
        assert f"baseline {name}: {row['deleted_links']} links deleted" in printed
    # without the option: no baselines
    assert main(["resolve", "--links", str(src), "--out", str(tmp_path / "o2.csv"),
                 "--report", str(tmp_path / "r2.json")]) == 0
    assert "baselines" not in json.loads((tmp_path / "r2.json").read_text())


def test_comm_graph_file(tmp_path):
    src = tmp_path / "in.csv"
    src.write_text(FIG1)
    g = tmp_path / "g.csv"
    g.write_text("0,1\n1,2\n2,3\n0,3\n0,2\n3,4\n")
    out = tmp_path / "out.csv"
    assert main(["resolve", "--links", str(src), "--out", str(out), "--comm-graph", str(g)]) == 0
    assert (read_run_links_csv(out).status == "deleted").sum() == 1


@pytest.mark.parametrize("text, graph, message", [
    ("0,0,1,0\n0,x,2,0\n", None, "in.csv:2: .*not an integer"),
    ("0,0,1,0\n1,1,1,2\n", None, "in.csv:2: .*self-link"),
    ("0,0,1,0\n1,0,0,0\n", None, "in.csv:2: .*duplicate"),
    ("0,0,1,0\n0,0,1,1\n", None, "in.csv:2: .*linked twice"),
    ("0,0,1\n", None, "in.csv:1: .*3 columns"),
    ("0,0,1,0\n0,0,2,0\n", "0,1\n", "in.csv:2: .*not neighbours"),
    ("0,0,1,0\n", "0,0\n", "g.csv:1: .*own neighbour"),
])
def test_bad_input_exits_2_naming_the_row(tmp_path, capsys, text, graph, message):
    src = tmp_path / "in.csv"
    src.write_text(text)
    args = ["resolve", "--links", str(src), "--out", str(tmp_path / "out.csv")]
    if graph is not None:
        (tmp_path / "g.csv").write_text(graph)
        args += ["--comm-graph", str(tmp_path / "g.csv")]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ")
    assert re.search(message, err), err
    assert not (tmp_path / "out.csv").exists()


def test_missing_file_and_out_equal_to_input(tmp_path, capsys):
    assert main(["resolve", "--links", str(tmp_path / "no.csv"), "--out", str(tmp_path / "o.csv")]) == 2
    src = tmp_path / "in.csv"
    src.write_text(FIG1)
    assert main(["resolve", "--links", str(src), "--out", str(src)]) == 2
    assert "input file" in capsys.readouterr().err
    assert src.read_text() == FIG1


def test_header_only_file(tmp_path):
    src = tmp_path / "in.csv"
    src.write_text("cam_i,feat_i,cam_j,feat_j\n")
    out = tmp_path / "out.csv"
    assert main(["resolve", "--links", str(src), "--out", str(out)]) == 0
    assert len(read_run_links_csv(out).links) == 0
    assert np.array_equal(read_run_links_csv(out).round, np.zeros(0))



def test_own_output_is_accepted_as_input(tmp_path, capsys):
    src, out1, out2 = tmp_path / "in.csv", tmp_path / "out1.csv", tmp_path / "out2.csv"
    src.write_text(FIG1)
    assert main(["resolve", "--links", str(src), "--out", str(out1)]) == 0
    assert main(["resolve", "--links", str(out1), "--out", str(out2)]) == 0
    printed = capsys.readouterr().out
    assert "conflictive sets: 0 before, 0 after" in printed and "deleted: 0 links" in printed
    first, second = read_run_links_csv(out1), read_run_links_csv(out2)
    # the deleted row stays deleted with its reason and round; nothing else is cut
    for key in ("status", "reason", "round"):
        assert getattr(second, key).tolist() == getattr(first, key).tolist()
    assert second.links.feat_j.tolist() == first.links.feat_j.tolist()


def test_a_run_outputs_truth_column_goes_through(tmp_path, capsys):
    """A run-formation links.csv (with its ground truth) resolved again keeps each row's
    truth; a bad truth value is named."""
    src, out = tmp_path / "run.csv", tmp_path / "o.csv"
    src.write_text("cam_i,feat_i,cam_j,feat_j,status,reason,round,truth\n"
                   "0,0,1,0,kept,,,1\n1,0,2,0,kept,,,0\n0,1,2,1,deleted,resolution,3,1\n"
                   "2,2,0,2,kept,,,\n")
    assert main(["resolve", "--links", str(src), "--out", str(out)]) == 0
    assert [r.rsplit(",", 1)[1] for r in out.read_text().splitlines()[1:]] == ["1", "0", "1", ""]
    src.write_text("cam_i,feat_i,cam_j,feat_j,status,reason,round,truth\n0,0,1,0,kept,,,yes\n")
    assert main(["resolve", "--links", str(src), "--out", str(tmp_path / "x.csv")]) == 2
    assert "truth 'yes' is not 1 (good), 0 (spurious) or empty" in capsys.readouterr().err


def test_run_links_csv_with_a_bad_status_names_the_row(tmp_path, capsys):
    src = tmp_path / "in.csv"
    src.write_text("cam_i,feat_i,cam_j,feat_j,status,reason,round,truth\n0,0,1,0,maybe,,,\n")
    assert main(["resolve", "--links", str(src), "--out", str(tmp_path / "o.csv")]) == 2
    assert re.search(r"in.csv:2: .*status 'maybe'", capsys.readouterr().err)


def test_a_clean_h5_links_csv_with_deleted_not_one_to_one_rows_is_read(tmp_path, capsys):
    """clean-db and clean-h5 write the rows that break one-to-one-ness as deleted: resolve
    reads such a links.csv (its deleted rows stay deleted) and still refuses kept rows that
    break it."""
    head = "cam_i,feat_i,cam_j,feat_j,status,reason,round,truth\n"
    src, out = tmp_path / "in.links.csv", tmp_path / "o.csv"
    src.write_text(head + "0,0,1,0,kept,,,\n0,1,1,0,deleted,not-one-to-one,,\n"
                          "1,0,2,0,kept,,,\n2,0,0,1,kept,,,\n")
    assert main(["resolve", "--links", str(src), "--out", str(out)]) == 0
    back = read_run_links_csv(out)
    assert back.status.tolist()[1] == "deleted" and back.reason.tolist()[1] == "not-one-to-one"
    kept = back.links.subset(back.status == "kept")
    m = features_per_camera_for(back.links)
    assert count_conflicts(AssociationGraph(m, kept)).conflictive_sets == 0
    src.write_text(head + "0,0,1,0,kept,,,\n0,1,1,0,kept,,,\n")
    assert main(["resolve", "--links", str(src), "--out", str(tmp_path / "x.csv")]) == 2
    assert "in.links.csv:3: '0,1,1,0,kept,,,': not one-to-one" in capsys.readouterr().err


def test_deleted_rows_between_non_neighbours_are_read_with_the_comm_graph(tmp_path, capsys):
    """clean-db deletes the links between images that are not neighbours (not-comm-edge):
    its links.csv resolved again with the same comm graph keeps them deleted; a kept link
    between non-neighbours is still refused."""
    head = "cam_i,feat_i,cam_j,feat_j,status,reason,round,truth\n"
    src, graph, out = tmp_path / "in.links.csv", tmp_path / "g.csv", tmp_path / "o.csv"
    graph.write_text("0,1\n1,2\n")
    src.write_text(head + "0,0,1,0,kept,,,\n1,0,2,0,kept,,,\n0,1,2,0,deleted,not-comm-edge,,\n")
    assert main(["resolve", "--links", str(src), "--comm-graph", str(graph),
                 "--out", str(out)]) == 0
    back = read_run_links_csv(out)
    assert back.status.tolist() == ["kept", "kept", "deleted"]
    assert back.reason.tolist()[2] == "not-comm-edge"
    src.write_text(head + "0,0,1,0,kept,,,\n0,1,2,0,kept,,,\n")
    assert main(["resolve", "--links", str(src), "--comm-graph", str(graph),
                 "--out", str(tmp_path / "x.csv")]) == 2
    assert "in.links.csv:3: link (0,1)-(2,0) joins cameras 0 and 2, which are not neighbours" \
        in capsys.readouterr().err


def test_a_links_csv_of_deleted_rows_only_has_nothing_to_associate(tmp_path, capsys):
    """A run-output links.csv whose rows were all deleted by an earlier run: this run has no
    link to associate and cuts none, so it warns 'no-links' (naming rows already deleted),
    not that every input link was cut."""
    src, out, rep = tmp_path / "in.csv", tmp_path / "o.csv", tmp_path / "r.json"
    src.write_text("cam_i,feat_i,cam_j,feat_j,status,reason,round,truth\n"
                   "0,0,1,0,deleted,resolution,3,\n1,0,2,0,deleted,resolution,3,\n")
    assert main(["resolve", "--links", str(src), "--out", str(out), "--report", str(rep)]) == 0
    err = capsys.readouterr().err
    assert "there is nothing to associate" in err and "only rows already deleted" in err
    assert "was cut" not in err
    assert [w["code"] for w in json.loads(rep.read_text())["warnings"]] == ["no-links"]
    assert read_run_links_csv(out).status.tolist() == ["deleted", "deleted"]
