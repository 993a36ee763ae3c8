"""A graph that is no kind and no file: the kinds listed are those the command takes (knn:K
only where neighbours can be picked by image similarity)."""

import pytest

from pipeline.commgraph import comm_graph
from pipeline.errors import InputError


@pytest.mark.parametrize("kwargs, knn_listed", [
    ({}, True),                     # run-images
    ({"offers_knn": False}, False),  # run-landmarks
    ({"what": "robot"}, False),      # run-images --sequence: the robots' graph
])
@pytest.mark.parametrize("spec", ["bogus", ""])
def test_unknown_graph_lists_only_the_kinds_offered(spec, kwargs, knn_listed, tmp_path,
                                                    monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(InputError) as err:
        comm_graph(spec, ["a", "b", "c"], **kwargs)
    assert "ring2" in str(err.value)
    assert ("knn:K" in str(err.value)) is knn_listed


def test_run_landmarks_does_not_offer_knn(capsys, tmp_path):
    from pathlib import Path

    from pipeline.__main__ import main

    hotel = Path(__file__).resolve().parents[1] / "data" / "cmu_hotel_small"
    assert main(["run-landmarks", str(hotel), "--graph", "complete2",
                 "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err
    assert "graph 'complete2': not one of" in err and "knn:K" not in err
