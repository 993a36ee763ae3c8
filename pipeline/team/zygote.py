"""The robots' zygote: import the robot program once, then fork every robot of a team.

Started by :func:`pipeline.team.launcher.launch_team` as ``python -m pipeline.team.zygote TEAM.json
WORKDIR``. A robot process spends most of its start in the interpreter and its imports
(NumPy, SciPy, OpenCV, Zenoh, the pipeline): with ``n`` robots on a few cores that is ``n``
times the same work. The zygote does it once, then ``fork()`` s one child per robot, each of
which runs exactly what ``python -m pipeline robot --team TEAM.json --id I`` runs (its output
in ``WORKDIR/robotI.log``). It is safe to fork here: the zygote has imported modules but
started no thread and opened no Zenoh session (each robot opens its own after the fork).

Protocol on the zygote's standard output (one line each, for the launcher): ``pid I PID``
once robot ``I`` is forked, ``exit I CODE`` when it ended (``CODE`` as
:func:`os.waitstatus_to_exitcode`: negative for a signal).

No process is left behind: every robot asks the kernel to kill it when the zygote dies
(``PR_SET_PDEATHSIG``), the zygote asks the same of the launcher, and all of them are in the
launcher's process group, which it kills on any exit.
"""

from __future__ import annotations

import os
import sys
import traceback

__all__ = ["main", "PRELOAD"]

#: modules a robot imports on its way; imported once by the zygote
PRELOAD = ("numpy", "scipy.sparse", "scipy.sparse.csgraph", "scipy.special", "cv2", "zenoh",
           "data_synth", "pipeline.matching.features", "pipeline.matching.pairs", "pipeline.matching.link_evidence",
           "pipeline.inputs.photos", "pipeline.inputs.linkscsv", "pipeline.consistency.termination",
           "pipeline.consistency.evidence", "pipeline.fusion.robot", "pipeline.fusion.robot_loops",
           "pipeline.team.robot",
           "pipeline.transport.zenoh_transport", "pipeline.commands.robot", "pipeline.__main__")


def _robot(team_path: str, i: int, log_path: str, zygote_pid: int) -> None:
    """The child: robot ``i``, its output in its log; never returns. It dies with the zygote
    (``zygote_pid``), even one that died before the child ran
    (:func:`pipeline.team.launcher.die_with_parent`)."""
    code = 1
    try:
        fd = os.open(log_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        os.dup2(fd, 1)
        os.dup2(fd, 2)
        os.close(fd)
        from pipeline.team.launcher import die_with_parent

        die_with_parent(zygote_pid)
        from pipeline.__main__ import main as cli

        code = cli(["robot", "--team", team_path, "--id", str(i)])
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 1
    except BaseException:  # noqa: BLE001 - reported in the robot's log, exit code 1
        traceback.print_exc()
    finally:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except Exception:  # noqa: BLE001 - the log may be gone
                pass
        os._exit(int(code or 0))


def main(argv: list[str] | None = None) -> int:
    """``python -m pipeline.team.zygote TEAM.json WORKDIR``."""
    import importlib

    team_path, workdir = (argv if argv is not None else sys.argv[1:])[:2]
    for name in PRELOAD:
        importlib.import_module(name)
    from pipeline.team.teamfile import load_team

    team = load_team(team_path)
    children: dict[int, int] = {}
    me = os.getpid()
    for i in range(team.n):
        sys.stdout.flush()
        sys.stderr.flush()
        pid = os.fork()
        if pid == 0:
            _robot(team_path, i, os.path.join(workdir, f"robot{i}.log"), me)
        children[pid] = i
        print(f"pid {i} {pid}", flush=True)
    while children:
        try:
            pid, status = os.wait()
        except ChildProcessError:
            break
        i = children.pop(pid, None)
        if i is not None:
            print(f"exit {i} {os.waitstatus_to_exitcode(status)}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
