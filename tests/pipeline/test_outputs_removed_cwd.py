"""A command started in a folder removed since (a shell left in a deleted build folder): an
absolute --out of run-formation or run-images was refused with 'error: No such file or
directory', naming nothing, and a relative one said the same; an absolute --out is now
written, a relative one refused saying why."""

import os

import pytest

from pipeline.__main__ import main


@pytest.fixture
def removed_cwd(tmp_path, monkeypatch):
    gone = tmp_path / "gone"
    gone.mkdir()
    monkeypatch.chdir(gone)
    gone.rmdir()
    return tmp_path


def test_relative_outputs_are_refused_naming_the_removed_folder(removed_cwd, capsys):
    links = removed_cwd / "links.csv"
    links.write_text("0,0,1,0\n1,0,2,0\n")
    for argv in (["resolve", "--links", str(links), "--out", "rel.csv"],
                 ["run-formation", "--size", "160x120", "--max-features", "50", "--no-rerun"]):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert "is relative to the current folder, which was removed" in err, err
    assert sorted(os.listdir(removed_cwd)) == ["links.csv"]


def test_an_absolute_run_folder_is_written(removed_cwd, capsys, monkeypatch):
    monkeypatch.setenv("FORMATION_MATCH_CACHE", "off")
    out = removed_cwd / "run"
    assert main(["run-formation", "--size", "160x120", "--max-features", "50", "--no-rerun",
                 "--no-fusion", "--out", str(out)]) in (0, 3)
    assert (out / "report.json").is_file()
