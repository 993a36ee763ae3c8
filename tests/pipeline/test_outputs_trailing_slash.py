"""An output file given with a trailing '/' (``resolve --out results/``): Path('results/')
reads as the file 'results', so the links were written to a file of that name, where a
folder was meant; ``--out -`` wrote a file named '-', where stdout was meant."""

import pytest

from pipeline.__main__ import main
from pipeline.errors import InputError
from pipeline.outputs import check_output_files


def test_a_file_output_ending_with_a_slash_is_refused(tmp_path):
    with pytest.raises(InputError, match=r"--report '.*results/' ends with '/', so it names a "
                                         r"folder; give the name of a file to write"):
        check_output_files([("--out", tmp_path / "o.csv"), ("--report", f"{tmp_path}/results/")])


def test_resolve_writes_nothing_for_such_an_out(tmp_path, capsys):
    links = tmp_path / "links.csv"
    links.write_text("0,0,1,0\n1,0,2,0\n")
    assert main(["resolve", "--links", str(links), "--out", f"{tmp_path}/results/"]) == 2
    assert "ends with '/'" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["links.csv"]


def test_a_dash_is_no_stdout(tmp_path, monkeypatch, capsys):
    links = tmp_path / "links.csv"
    links.write_text("0,0,1,0\n1,0,2,0\n")
    monkeypatch.chdir(tmp_path)
    assert main(["resolve", "--links", str(links), "--out", "-"]) == 2
    assert "--out '-': outputs are written to files, never to stdout" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["links.csv"]
    assert main(["resolve", "--links", str(links), "--out", "./-"]) == 0
    assert (tmp_path / "-").is_file()
