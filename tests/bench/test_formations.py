"""bench/formations.py hands its --out to run-formations, which runs in the repository: a
relative --out must be the caller's (it was read there, and written in the repository)."""

import subprocess
import sys

from benchload import load_bench


def test_a_relative_out_is_the_callers(tmp_path, monkeypatch, capsys):
    bench = load_bench("formations")
    seen = []

    def run(cmd, **kw):  # stands for the run-formations process (minutes of work)
        seen.append(cmd)
        return subprocess.CompletedProcess(cmd, 2, "", "error: stopped by the test")

    monkeypatch.setattr(bench.subprocess, "run", run)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "argv", ["formations.py", "--out", "mine"])
    assert bench.main() == 2
    (cmd,) = seen
    assert cmd[cmd.index("--out") + 1] == str(tmp_path / "mine")
