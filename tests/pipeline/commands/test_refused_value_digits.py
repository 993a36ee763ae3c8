"""A number refused just past its limit is named with its own digits: the messages wrote it
with ``{:g}``, which rounds 1000001 to ``1e+06`` and 120.0000001 to ``120``, so the error
named the limit itself as the bad value (``--speed 1e+06: expected ... from 0 to 1e+06``)."""

import json

import pytest

from pipeline.__main__ import main


@pytest.mark.parametrize("args, named", [
    (["run-formation", "--steps", "2", "--speed", "1000001"],
     "error: --speed 1000001.0: expected a finite number of metres per step from 0 to 1e+06"),
    (["run-formation", "--merge-radius", "120.0000001"],
     "error: --merge-radius 120.0000001: expected pixels from 0 (merges nothing) to 120,"),
    (["run-formation", "--merge-radius", "1e9"],
     "error: --merge-radius 1e+09: expected pixels from 0 (merges nothing) to 120,"),
])
def test_run_formation_names_the_refused_number_as_given(tmp_path, capsys, args, named):
    out = tmp_path / "run"
    assert main([*args, "--size", "160x120", "--max-features", "50", "--no-rerun",
                 "--out", str(out)]) == 2
    assert named in capsys.readouterr().err
    assert not out.exists()


def test_observe_names_a_timeout_just_past_its_limit(tmp_path, capsys):
    doc = {"version": 1, "name": "two", "comm_edges": [[0, 1]],
           "robots": [{"id": 0, "endpoint": "tcp/127.0.0.1:7447"},
                      {"id": 1, "endpoint": "tcp/127.0.0.1:7448"}],
           "observer": {"endpoint": "tcp/127.0.0.1:7449"},
           "data": {"kind": "formation", "formation": "line", "robots": 2, "seed": 0}}
    (tmp_path / "T.json").write_text(json.dumps(doc))
    assert main(["observe", "--team", str(tmp_path / "T.json"), "--out", str(tmp_path / "o"),
                 "--timeout", "86400.01"]) == 2
    assert "error: --timeout 86400.01 must be a number of seconds in (0, 86400]" in \
        capsys.readouterr().err
