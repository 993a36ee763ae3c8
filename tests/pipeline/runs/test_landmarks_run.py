"""The default run folder of run-landmarks (LandmarksConfig.out_dir)."""

from pathlib import Path

import numpy as np
import pytest

from pipeline.runs.landmarks import LandmarksConfig


def test_a_graph_file_names_the_default_run_folder_by_its_stem(tmp_path):
    """--graph FILE without --out: the folder was runs/landmarks-DIR-<the file's path>, which
    nested folders (runs/landmarks-hotel-/tmp/x/g.csv/) and, with '..' in the path, put the run
    outside runs/."""
    graph = tmp_path / "sub" / "edges.csv"
    graph.parent.mkdir()
    graph.write_text("0,1\n")
    for given in (str(graph), str(tmp_path / "sub" / ".." / "sub" / "edges.csv")):
        out = LandmarksConfig(directory=str(tmp_path / "hotel"), graph=given).out_dir()
        assert out == Path("runs") / "landmarks-hotel-edges"


def test_a_graph_kind_names_the_default_run_folder():
    assert LandmarksConfig(directory="data/hotel", graph="seq:4", frames=20).out_dir() == \
        Path("runs") / "landmarks-hotel-f20-seq4"


def test_votes_that_remove_every_match_are_named_in_the_warning(votes_remove_every_match):
    """Three images of two landmarks whose Hungarian matches form one inconsistent cycle
    (a-b swapped, a-c and b-c not): every pair's two-hop vote ties with its direct one, so
    the votes keep no match. The no-links warning blamed a --ratio gate or the --graph,
    neither of which this run has; it now names the votes and the 6 matches they removed."""
    from pipeline.runs.landmarks import run_landmarks

    tmp_path = votes_remove_every_match
    config = LandmarksConfig(directory=str(tmp_path), geometry="none", resolution="paper",
                             baselines=False, out=str(tmp_path / "run"))
    _, report = run_landmarks(config)
    assert report["pairwise"]["input_links"]["predicted_pairs"] == 6
    assert report["before"]["links"] == 0
    [warning] = report["warnings"]
    assert warning["code"] == "no-links"
    assert "--refine votes step removed all 6 matches" in warning["message"]
    assert "--ratio" not in warning["message"]


def test_the_load_line_counts_the_landmarks_of_every_image(tmp_path, capsys):
    """Two of three images hide a landmark ('nan nan' rows): the load line said "3 images x 3
    landmarks" from the first image's count alone; it now gives the range the images see."""
    import numpy as np
    from PIL import Image

    from pipeline.__main__ import main

    data = tmp_path / "data"
    data.mkdir()
    pts = np.array([[10.0, 12.0], [30.0, 20.0], [50.0, 40.0], [20.0, 30.0]])
    for k in range(3):
        Image.new("L", (64, 48), 128).save(data / f"v{k}.png")
        rows = pts.copy()
        if k < 2:  # v0 and v1 hide one landmark each, v2 sees all four
            rows[k + 1] = np.nan
        np.savetxt(data / f"v{k}.txt", rows)
    assert main(["run-landmarks", str(data), "--geometry", "none", "--no-baselines",
                 "--out", str(tmp_path / "run")]) == 0
    err = capsys.readouterr().err
    assert "3 images seeing 3-4 landmarks, vector descriptors (sift)" in err


def test_the_matching_of_the_largest_image_pair_is_counted_against_the_memory_limit():
    """--max-memory-gb counted the links, the detection and the baselines, not the matching:
    two images of 5,000 landmarks ran to a 0.74 GB peak under a 0.3 GB limit. The largest
    image pair of the comm graph is now counted before the matching."""
    from pipeline.budget import BYTES_PER_LANDMARK_PAIR
    from pipeline.errors import InputError
    from pipeline.runs.landmarks import LandmarksConfig, _check_matching_memory

    config = LandmarksConfig(directory="unused", max_memory_gb=0.1)
    m = np.array([3000, 100, 3000])
    with pytest.raises(InputError, match=r"matching images 0 and 2 \(3000 x 3000 landmark pairs\) "
                                         r"would need about 0\.2 GB of memory, above the limit "
                                         r"of 0\.1 GB; match fewer landmarks per image"):
        _check_matching_memory(m, np.array([[0, 1], [0, 2], [1, 2]]), config)
    # a graph without the large pair, and no graph at all, pass
    _check_matching_memory(m, np.array([[0, 1], [1, 2]]), config)
    _check_matching_memory(m, np.zeros((0, 2), np.int64), config)
    assert 3000 * 3000 * BYTES_PER_LANDMARK_PAIR > 0.1e9 > 3000 * 100 * BYTES_PER_LANDMARK_PAIR


@pytest.mark.parametrize("resolution", ["sync", "evidence", "paper"])
def test_deleted_by_case_counts_every_cut_of_the_rule(votes_remove_every_match, tmp_path,
                                                      resolution):
    """deleted_by_case named only Alg. 1's cases (b) and (c): the cuts of sync and evidence
    were counted nowhere, so the cases summed to 0 beside deleted_links > 0."""
    import json

    from pipeline.__main__ import main

    out = tmp_path / "run"
    main(["run-landmarks", str(votes_remove_every_match), "--refine", "none", "--geometry",
          "none", "--no-baselines", "--resolution", resolution, "--out", str(out)])
    r = json.loads((out / "report.json").read_text())["resolution"]
    assert r["deleted_links"] > 0
    assert sum(r["deleted_by_case"].values()) == r["deleted_links"]


def test_the_table_labels_the_closure_f1_as_the_readme_does():
    """The closure's F1 row was labelled 'Pairwise f1', the report key, beside the README's
    and the table's own 'F1' rows."""
    from pipeline.runs.landmarks import landmarks_markdown

    score = {"precision": 1.0, "recall": 0.5, "f1": 2 / 3, "predicted_pairs": 1,
             "true_pairs": 2, "correct_pairs": 1}
    counts = {"links": 1, "good_links": 1, "spurious_links": 0, "missing_links": 1,
              "association_sets": 1, "conflictive_sets": 0}
    report = {"title": "t", "before": counts, "after": counts, "baselines": {},
              "pairwise": {"before": score, "after": score, "input_links": score,
                           "before_links": score},
              "cycle_consistent": True, "cycle_consistent_before": True,
              "refinement": {"method": "none"},
              "resolution": {"method": "sync", "deleted_links": 0, "good_deleted": 0,
                             "spurious_deleted": 0, "iterations": 0, "detection_rounds": 0,
                             "resolution_rounds": 0, "messages": 0, "bytes": 0, "time_s": 0.0}}
    md = landmarks_markdown(report)
    assert "| Pairwise F1 (closure) | 0.667 | 0.667 |" in md
    assert "Pairwise f1" not in md
