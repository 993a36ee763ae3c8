"""An output file given with a trailing '/' (``resolve --out results/``): Path('results/')
reads as the file 'results', so the links were written to a file of that name, where a
folder was meant."""

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
