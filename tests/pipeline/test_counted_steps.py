"""A count printed with 'steps' (or 'links', 'frames') said '1 steps', '1 links': the summary
of run-formation --steps 1, the report's title, the stage lines, the no-links warning and the
memory budget now say '1 step' and '1 link'."""

import json

import pytest

from pipeline.__main__ import main
from pipeline.errors import InputError


def test_counted_says_the_singular_of_one_only():
    from pipeline.progress import counted

    assert [counted(n, "step") for n in (0, 1, 2)] == ["0 steps", "1 step", "2 steps"]


def test_an_online_run_of_one_step_says_one_step(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["run-formation", "--steps", "1", "--robots", "2", "--graph", "line", "--size",
                 "96x72", "--max-features", "80", "--no-fusion", "--no-rerun", "--out",
                 str(out)]) == 0
    captured = capsys.readouterr()
    summary = next(line for line in captured.out.splitlines() if "conflict-free after" in line)
    assert summary.startswith("1 step, ")
    assert "[render] 1 step ..." in captured.err and "[online] 1 step, window" in captured.err
    report = json.loads((out / "report.json").read_text())
    assert "(1 step, seed 0)" in report["title"]
    assert "1 steps" not in captured.out + captured.err + report["title"]


def test_the_no_links_warning_of_one_step_says_one_step():
    from pipeline.outcome import flag_online

    report = flag_online({"steps": [{"conflictive_sets_after": 0}], "final": {"links": 0}})
    assert report["warnings"][0]["message"].startswith("no link in 1 step: ")


def test_the_memory_budget_of_one_frame_says_one_step_and_one_frame():
    from pipeline.budget import check_motion_memory

    with pytest.raises(InputError, match=r"rendering 1 step of 1 robots at 40x30 \(1 frame\)"):
        check_motion_memory(1, 1, (40, 30), 1e-9)
