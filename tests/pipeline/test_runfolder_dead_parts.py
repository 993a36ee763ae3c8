"""The temporary files of an output left by a command killed while writing it (kill -9, the
OOM killer) are removed by the next command writing that output: resolve, clean-db and clean-h5
left a hidden `.OUT.*.part.EXT` (with a database or recording writer's own files beside it)
at every kill, and they piled up, a full copy of the database each."""

import os
import signal
import subprocess
import sys
import textwrap

from pipeline.runfolder import OutputFiles

_KILLED_WRITER = textwrap.dedent("""
    import os, signal, sys
    from pipeline.runfolder import OutputFiles
    out = OutputFiles(replace=True)
    part = out.path(sys.argv[1], "--out")
    part.write_text("half a file")
    open(f"{part.parent}/.{part.name}.ab12cd.tmp", "w").write("a writer's own temporary")
    print(part.name, flush=True)
    os.kill(os.getpid(), signal.SIGKILL)
""")


def _killed_writer(target):
    proc = subprocess.run([sys.executable, "-c", _KILLED_WRITER, str(target)],
                          capture_output=True, text=True, timeout=120, cwd=os.getcwd())
    assert proc.returncode == -signal.SIGKILL, proc.stderr
    return proc.stdout.strip()


def test_a_killed_commands_temporary_files_are_removed_by_the_next(tmp_path):
    target = tmp_path / "out.csv"
    target.write_text("previous result\n")
    name = _killed_writer(target)
    assert name.startswith(".out.") and name.endswith(".part.csv")
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        ["out.csv", name, f".{name}.ab12cd.tmp"])
    assert target.read_text() == "previous result\n"  # the kill left the previous output
    with OutputFiles(replace=True) as out:
        out.path(target, "--out").write_text("new result\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.csv"]
    assert target.read_text() == "new result\n"


def test_a_live_commands_and_a_users_files_are_kept(tmp_path):
    target = tmp_path / "out.csv"
    mine = [".out.123-456-abcdabcd-000000000000.part.csv",  # a digest of no run
            ".out.links.csv", ".out.csv.bak", "out.part.csv"]
    for name in mine:
        (tmp_path / name).write_text("the user's")
    other = _killed_writer(tmp_path / "other.csv")  # another output's: not this one's to drop
    with OutputFiles(replace=True) as first:  # alive while the second starts
        live = first.path(target, "--out")
        live.write_text("first")
        with OutputFiles(replace=True) as second:
            assert live.exists()
            second.path(target, "--out").write_text("second")
        assert live.exists()
    assert target.read_text() == "first"
    for name in mine + [other]:
        assert (tmp_path / name).exists(), name


_KILLED_JSON_WRITER = textwrap.dedent("""
    import os, signal, sys
    from pipeline.runfolder import OutputFiles, atomic_file
    target = sys.argv[1]
    if sys.argv[2] == "nested":  # --report of resolve: a JSON written atomically into a part
        target = OutputFiles(replace=True).path(target, "--report")
    with atomic_file(target) as f:
        f.write('{"half": ')
        f.flush()
        os.kill(os.getpid(), signal.SIGKILL)
""")


def test_a_file_written_atomically_by_a_killed_command_leaves_nothing_after_the_next(tmp_path):
    # a bench's results.json (write_json_atomic), and a command's --report inside its part
    from pipeline.runfolder import write_json_atomic

    target = tmp_path / "results.json"
    target.write_text('{"previous": 1}\n')
    for how in ("alone", "nested"):
        proc = subprocess.run([sys.executable, "-c", _KILLED_JSON_WRITER, str(target), how],
                              capture_output=True, text=True, timeout=120, cwd=os.getcwd())
        assert proc.returncode == -signal.SIGKILL, proc.stderr
        assert len(list(tmp_path.iterdir())) == (2 if how == "alone" else 3)
        if how == "alone":
            write_json_atomic(target, {"new": 1})
        else:
            with OutputFiles(replace=True) as out:
                write_json_atomic(out.path(target, "--report"), {"new": 2})
        assert sorted(p.name for p in tmp_path.iterdir()) == ["results.json"], how
    assert target.read_text() == '{\n  "new": 2\n}\n'


def test_a_long_output_name_still_leaves_room_for_its_writers_files(tmp_path):
    # a 225-byte name: the temporary name carrying its process would leave no room for a JSON
    # written atomically into it (its own temporary beside it): the short one is used
    from pipeline.runfolder import write_json_atomic

    target = tmp_path / ("a" * 220 + ".json")
    with OutputFiles(replace=True) as out:
        write_json_atomic(out.path(target, "--report"), {"ok": 1})
    assert sorted(p.name for p in tmp_path.iterdir()) == [target.name]
