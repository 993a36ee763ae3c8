"""The observer refuses a team whose feature method this OpenCV build lacks before it listens:
every robot refuses it at its start, so the observer waited ``--timeout`` (600 s by default)
for robots that never started and then named them as not started."""

import json

import pytest

from pipeline.__main__ import main
from pipeline.matching.features import surf_available


@pytest.mark.skipif(surf_available(), reason="this OpenCV build has SURF")
def test_observe_refuses_a_feature_method_the_robots_refuse_before_it_listens(
        tmp_path, capsys, monkeypatch):
    import pipeline.team.observe as observing

    def listened(*a, **k):
        raise AssertionError("the observer listened")

    monkeypatch.setattr(observing, "observe_team", listened)
    doc = {"version": 1, "name": "two", "comm_edges": [[0, 1]],
           "robots": [{"id": 0, "endpoint": "tcp/127.0.0.1:7447"},
                      {"id": 1, "endpoint": "tcp/127.0.0.1:7448"}],
           "observer": {"endpoint": "tcp/127.0.0.1:7449"},
           "data": {"kind": "formation", "formation": "line", "robots": 2, "seed": 0,
                    "size": [160, 120]},
           "options": {"features": "surf"}}
    (tmp_path / "T.json").write_text(json.dumps(doc))
    assert main(["observe", "--team", str(tmp_path / "T.json"), "--out",
                 str(tmp_path / "o"), "--timeout", "600", "--no-rerun"]) == 2
    err = capsys.readouterr().err
    assert "error: team 'two': option features: feature method 'surf' is not available" in err
    assert "use one of sift, orb, akaze" in err
    assert not (tmp_path / "o").exists()
