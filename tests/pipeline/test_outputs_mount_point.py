"""A mount point given as a run folder is refused before any work: a run folder is put in
place by renaming, which a mount point cannot be, and the run failed at its very end with
'Device or resource busy', all its work lost."""

import os
import subprocess

import pytest

from pipeline.errors import InputError
from pipeline.outputs import check_run_folder


def test_a_mount_point_is_refused_naming_a_folder_inside_it(tmp_path, monkeypatch):
    mnt = tmp_path / "disk"
    mnt.mkdir()
    real_ismount = os.path.ismount
    monkeypatch.setattr(os.path, "ismount", lambda p: os.fspath(p) == str(mnt) or real_ismount(p))
    with pytest.raises(InputError, match=r"--out '.*disk' is a mount point; .* e\.g\. '.*disk/run'"):
        check_run_folder(mnt)
    check_run_folder(mnt / "run")  # a folder inside it is fine


def test_a_bind_mount_of_the_same_file_system_is_seen(tmp_path):
    src, dst = tmp_path / "src", tmp_path / "a dst"  # a space: escaped in mountinfo
    src.mkdir()
    dst.mkdir()
    if os.geteuid() != 0 or subprocess.run(["mount", "--bind", str(src), str(dst)],
                                           capture_output=True).returncode != 0:
        pytest.skip("needs a bind mount (root)")
    try:
        assert not os.path.ismount(dst)  # what os.path.ismount alone misses
        with pytest.raises(InputError, match="is a mount point"):
            check_run_folder(dst)
    finally:
        subprocess.run(["umount", str(dst)], check=True)
