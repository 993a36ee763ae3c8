"""A pairwise score that is 0/0 (precision without a predicted pair, recall without a true
pair, F1 without either) is printed as '–', not as a measured 0.000; report.json keeps the
0.0 it is computed as."""

import json

import numpy as np
import pytest

from pipeline.evaluation.metrics import pairwise_scores, score_text

NO_PAIR = np.zeros((0, 2), np.int64)


@pytest.mark.parametrize("predicted, truth, printed", [
    (NO_PAIR, NO_PAIR, ["–", "–", "–"]),
    (NO_PAIR, [[0, 1]], ["–", "0.000", "0.000"]),
    ([[0, 1]], NO_PAIR, ["0.000", "–", "0.000"]),
    ([[0, 1]], [[1, 2]], ["0.000", "0.000", "0.000"]),
    ([[0, 1], [1, 2]], [[1, 2]], ["0.500", "1.000", "0.667"]),
])
def test_a_score_of_no_pairs_is_printed_as_not_defined(predicted, truth, printed):
    s = pairwise_scores(np.asarray(predicted), np.asarray(truth), 3)
    assert [score_text(s, k) for k in ("precision", "recall", "f1")] == printed
    assert all(isinstance(s[k], float) for k in ("precision", "recall", "f1"))


def test_the_landmarks_table_prints_a_precision_of_no_predicted_pair_as_not_defined(
        votes_remove_every_match):
    """Votes that remove every match leave no predicted pair: the table printed its
    precision, and each baseline's, as 0.000."""

    from pipeline.runs.landmarks import LandmarksConfig, landmarks_markdown, run_landmarks

    tmp_path = votes_remove_every_match
    config = LandmarksConfig(directory=str(tmp_path), geometry="none", resolution="paper",
                             out=str(tmp_path / "run"))
    out, report = run_landmarks(config)
    assert report["pairwise"]["before"]["predicted_pairs"] == 0
    table = landmarks_markdown(report)
    assert "| Pairwise precision (closure) | – | – |" in table
    assert "| Pairwise recall (closure) | 0.000 | 0.000 |" in table  # 6 true pairs, none found
    assert "| clear | – | 0.000 | 0.000 |" in table
    saved = json.loads((out / "report.json").read_text())
    assert saved["pairwise"]["before"]["precision"] == 0.0
