"""A copy that fails on a full disk names the file on that disk: shutil.copyfile's error names
the source first (run-images --export-db on a full --out printed the temporary database under
/tmp, a disk with room)."""

import errno
import importlib

from pipeline.__main__ import main


def _fails_with(monkeypatch, capsys, exc):
    mod = importlib.import_module("pipeline.commands.resolve")

    def run(args):
        raise exc

    monkeypatch.setattr(mod, "run", run)
    assert main(["resolve", "--links", "in.csv", "--out", "out.csv"]) == 2
    return capsys.readouterr().err.strip()


def test_a_full_disk_during_a_copy_names_the_destination(monkeypatch, capsys):
    exc = OSError(errno.ENOSPC, "No space left on device", "/tmp/work/database.db", None,
                  "/mnt/full/.run.tmp-x/database.db")
    assert _fails_with(monkeypatch, capsys, exc) == \
        "error: /mnt/full/.run.tmp-x/database.db: No space left on device"


def test_another_copy_error_names_both_files(monkeypatch, capsys):
    exc = OSError(errno.EIO, "Input/output error", "/a/src.db", None, "/b/dst.db")
    assert _fails_with(monkeypatch, capsys, exc) == \
        "error: /a/src.db -> /b/dst.db: Input/output error"


def test_an_error_of_one_file_names_it(monkeypatch, capsys):
    exc = OSError(errno.ENOSPC, "No space left on device", "/mnt/full/out.csv")
    assert _fails_with(monkeypatch, capsys, exc) == \
        "error: /mnt/full/out.csv: No space left on device"
