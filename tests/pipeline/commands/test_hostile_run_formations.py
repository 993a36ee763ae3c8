"""run-formations, as a hostile user would run it: a meaningless value is refused before any
formation is rendered, with one line on stderr and exit 2, and nothing is written."""

import sys
from pathlib import Path

import pytest

from pipeline.__main__ import main

sys.path.insert(0, str(Path(__file__).parent))
from hostile import one_line_error  # noqa: E402


@pytest.mark.parametrize("flag,value,message", [
    ("--seed", "-5", "--seed -5"),
    ("--size", "100000x100000", "too large"),
    ("--max-features", "99999999999999999999", "at most 1000000"),
    ("--max-features", "3", "at least 8"),
    ("--size", "4096x4096", "6 robots at 4096x4096 would need about 9.1 GB"),
])
def test_meaningless_values_are_refused_before_any_work(tmp_path, monkeypatch, capsys, flag,
                                                        value, message):
    import pipeline.runs.formation as run

    def never(*a, **k):
        raise AssertionError("a formation ran although the arguments are meaningless")

    monkeypatch.setattr(run, "run_formation", never)
    out = tmp_path / "runs"
    assert main(["run-formations", "--out", str(out), flag, value]) == 2
    one_line_error(capsys, message)
    assert not out.exists()


@pytest.mark.parametrize("file_name,text", [
    ("formations.md", "my own notes\n"),
    ("formations.json", '{"budget": 3}'),
])
def test_a_summary_file_it_did_not_write_is_never_replaced(tmp_path, monkeypatch, capsys,
                                                           file_name, text):
    import pipeline.runs.formation as run

    def never(*a, **k):
        raise AssertionError("a formation ran although --out holds a user's file")

    monkeypatch.setattr(run, "run_formation", never)
    out = tmp_path / "runs"
    out.mkdir()
    (out / file_name).write_text(text)
    assert main(["run-formations", "--out", str(out)]) == 2
    one_line_error(capsys, "--overwrite")
    assert (out / file_name).read_text() == text


def test_its_own_summary_is_replaced_and_a_user_file_only_with_overwrite(tmp_path):
    from pipeline.commands.run_formations import check_outputs, write_summaries
    from pipeline.errors import InputError

    out = tmp_path / "runs"
    out.mkdir()
    write_summaries(out, "# Formations (a)–(d), seed 0, sift, 320x240\n\n| |\n",
                    {"a": {"n_cameras": 4}, "d": {}})
    check_outputs(out, overwrite=False)  # a previous run's summary: replaced without asking
    # a user's files that look like ours (the title line, formation names as keys), or ours
    # edited since, are the user's: refused, and with --overwrite checked, not touched
    for name, text in (("formations.json", '{"a": {"my": "own data"}}'),
                       ("formations.md", "# Formations (a)–(d), seed 0, my notes\n")):
        saved = (out / name).read_text()
        (out / name).write_text(text)
        with pytest.raises(InputError, match=f"holds {name}, which run-formations did not"):
            check_outputs(out, overwrite=False)
        check_outputs(out, overwrite=True)
        assert (out / name).read_text() == text
        (out / name).write_text(saved)
    (out / "formations.md").write_text((out / "formations.md").read_text() + "my note\n")
    with pytest.raises(InputError, match="holds formations.md, which run-formations did not"):
        check_outputs(out, overwrite=False)
    check_outputs(out, overwrite=True)
    assert (out / "formations.md").read_text().endswith("my note\n")
    (out / "formations.md").write_text("my own notes\n")
    with pytest.raises(InputError, match="holds formations.md, which run-formations did not"):
        check_outputs(out, overwrite=False)
    check_outputs(out, overwrite=True)
    assert (out / "formations.md").read_text() == "my own notes\n"  # checked, not touched


def test_out_naming_a_file_or_a_foreign_run_folder_is_refused_before_any_work(
        tmp_path, monkeypatch, capsys):
    import pipeline.runs.formation as run

    monkeypatch.setattr(run, "run_formation", lambda *a, **k: pytest.fail("a formation ran"))
    a_file = tmp_path / "notes.txt"
    a_file.write_text("mine")
    assert main(["run-formations", "--out", str(a_file)]) == 2
    one_line_error(capsys, "is a file")
    assert a_file.read_text() == "mine"
    out = tmp_path / "runs"
    (out / "formation-c").mkdir(parents=True)
    (out / "formation-c" / "thesis.tex").write_text("mine")
    assert main(["run-formations", "--out", str(out)]) == 2
    one_line_error(capsys, "formation-c")
    assert (out / "formation-c" / "thesis.tex").read_text() == "mine"


def _fake_formation_runs(monkeypatch, seed_of_run, stop_at=None):
    """run_formation replaced by one that writes a small run folder (through the real
    atomic_run_folder) holding the seed, and raises KeyboardInterrupt at ``stop_at``."""
    import json

    import pipeline.runs.formation as run
    from pipeline.runfolder import atomic_run_folder

    def fake(cfg, *a, **k):
        if cfg.formation == stop_at:
            raise KeyboardInterrupt
        with atomic_run_folder(cfg.out_dir()) as tmp:
            (tmp / "report.json").write_text(json.dumps({"seed": seed_of_run}))
        return cfg.out_dir()

    monkeypatch.setattr(run, "run_formation", fake)
    import pipeline.commands.run_formations as rf
    monkeypatch.setattr(rf, "formations_table", lambda reports: "table\n")


def test_an_interrupt_replaces_no_formation_of_the_previous_run(tmp_path, monkeypatch, capsys):
    """Ctrl-C during formation c: the four formation folders and the summaries of the
    previous run stay as they were (before, a and b were already replaced while the message
    said nothing was)."""
    import json

    out = tmp_path / "runs"
    _fake_formation_runs(monkeypatch, 11)
    assert main(["run-formations", "--out", str(out), "--seed", "11"]) == 0
    before = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    _fake_formation_runs(monkeypatch, 12, stop_at="c")
    assert main(["run-formations", "--out", str(out), "--seed", "12"]) == 130
    assert "nothing was written or replaced" in capsys.readouterr().err
    after = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert after == before
    assert {json.loads((out / f"formation-{x}" / "report.json").read_text())["seed"]
            for x in "abcd"} == {11}
    assert sorted(p.name for p in out.iterdir()) == sorted(
        ["formation-a", "formation-b", "formation-c", "formation-d", "formations.md",
         "formations.json"])  # no staging folder or lock left
    _fake_formation_runs(monkeypatch, 12)
    assert main(["run-formations", "--out", str(out), "--seed", "12"]) == 0
    assert {json.loads((out / f"formation-{x}" / "report.json").read_text())["seed"]
            for x in "abcd"} == {12}


def test_out_naming_a_run_folder_is_refused_and_the_run_stays_replaceable(tmp_path, monkeypatch,
                                                                          capsys):
    """run-formations --out RUN, RUN a run-formation folder: the four runs and the summaries
    were written inside it, and the next run-formation --out RUN refused RUN as a folder
    holding 46 entries added after its run."""
    from pipeline.outputs import run_folder_problem
    from pipeline.runfolder import atomic_run_folder

    _fake_formation_runs(monkeypatch, seed_of_run=1)
    run = tmp_path / "formation-d"
    with atomic_run_folder(run) as tmp:
        (tmp / "report.json").write_text("{}")
    assert main(["run-formations", "--out", str(run)]) == 2
    one_line_error(capsys, "is a run folder")
    assert sorted(p.name for p in run.iterdir()) == [".formation-match-run", "report.json"]
    assert run_folder_problem(run) is None
    # a run folder inside a run folder (run-formation --out RUN/sub), through the same check
    from pipeline.errors import InputError
    from pipeline.outputs import check_run_folder

    with pytest.raises(InputError, match="is inside the run folder"):
        check_run_folder(run / "sub")
    assert main(["run-formations", "--out", str(tmp_path / "runs")]) == 0  # elsewhere: fine
