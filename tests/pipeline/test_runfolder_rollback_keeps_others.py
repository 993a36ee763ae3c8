"""A command whose outputs cannot all be put in place removes those it had put there, and
only those: another command with --overwrite may have replaced one of them meanwhile (two
clean-db into one OUT.db), and that command's file was deleted although it said it wrote it."""

import pytest

import pipeline.runfolder as runfolder
from pipeline.errors import InputError
from pipeline.runfolder import OutputFiles


def test_an_output_replaced_meanwhile_by_another_command_is_kept(tmp_path, monkeypatch):
    a, b = tmp_path / "out.db", tmp_path / "out.links.csv"
    publish = runfolder.publish

    def another_command_meanwhile(tmp, path, replace):
        if path == b:  # the other command (--overwrite) puts both its outputs in place
            for target in (a, b):
                other = tmp_path / f".other-{target.name}"
                other.write_text("the other command's")
                publish(other, target, replace=True)
        publish(tmp, path, replace)

    monkeypatch.setattr(runfolder, "publish", another_command_meanwhile)
    with pytest.raises(InputError, match="created by someone else"):
        with OutputFiles(replace=False) as out:
            out.path(a, "--out").write_text("mine")
            out.path(b, "--out").write_text("mine")
    assert a.read_text() == b.read_text() == "the other command's"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.db", "out.links.csv"]


def test_an_output_of_its_own_is_removed_when_another_cannot_be_put_in_place(tmp_path):
    a, b = tmp_path / "out.db", tmp_path / "out.links.csv"
    with pytest.raises(InputError, match="created by someone else"):
        with OutputFiles(replace=False) as out:
            out.path(a, "--out").write_text("mine")
            out.path(b, "--out").write_text("mine")
            b.write_text("someone else's")
    assert not a.exists() and b.read_text() == "someone else's"
