"""Helpers of the hostile-input tests: run the CLI in a subprocess under a memory cap."""

import resource
import subprocess
import sys

#: address-space cap of a subprocess run (bytes): a case that needs more fails
MEMORY_CAP = 1536 * 1024 * 1024


def _cap():
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_CAP, MEMORY_CAP))


def run_capped(args, cwd=None, timeout=120):
    """``python -m pipeline ARGS`` with at most :data:`MEMORY_CAP` of address space."""
    return subprocess.run([sys.executable, "-m", "pipeline", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, timeout=timeout, preexec_fn=_cap)


def tree(path):
    """``{relative path: bytes}`` of every file under ``path`` (to prove nothing changed)."""
    return {str(p.relative_to(path)): p.read_bytes() for p in sorted(path.rglob("*"))
            if p.is_file()}


def one_line_error(capsys, *needles) -> str:
    """The single ``error:`` line a command printed on stderr (no traceback), holding every
    one of ``needles``."""
    err = capsys.readouterr().err
    assert "Traceback" not in err
    lines = [ln for ln in err.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1, err
    for n in needles:
        assert n in lines[0], lines[0]
    return lines[0]


def refused(capsys, argv, folder, *needles) -> str:
    """``main(argv)`` exits 2 with one error line holding ``needles`` (see
    :func:`one_line_error`), and every file under ``folder`` is as it was."""
    from pipeline.__main__ import main

    before = tree(folder)
    assert main(argv) == 2
    line = one_line_error(capsys, *needles)
    assert tree(folder) == before
    return line
