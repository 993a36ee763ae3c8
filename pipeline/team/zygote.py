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

*Serving* (``python -m pipeline.team.zygote --serve``, :func:`serve`): one zygote for every
team of a job that starts several (an online run starts three per step). It imports once,
then reads one JSON line per team on its standard input (``{"tag", "team", "workdir",
"launched_at"}``) and forks that team's robots; its lines carry the tag (``pid TAG I PID``,
``exit TAG I CODE``). It ends when its input closes and its last robot has ended. It stays
single-threaded (a robot is forked from it), so it waits on its input and on its children
at once with ``select``: ``SIGCHLD`` wakes it through :func:`signal.set_wakeup_fd`.

No process is left behind: every robot asks the kernel to kill it when the zygote dies
(``PR_SET_PDEATHSIG``), the zygote asks the same of the launcher, and all of them are in the
launcher's process group, which it kills on any exit.
"""

from __future__ import annotations

import json
import os
import select
import signal
import sys
import traceback

__all__ = ["main", "serve", "PRELOAD"]

#: modules a robot imports on its way; imported once by the zygote
PRELOAD = ("numpy", "scipy.sparse", "scipy.sparse.csgraph", "scipy.special", "cv2", "zenoh",
           "data_synth", "pipeline.matching.features", "pipeline.matching.pairs", "pipeline.matching.link_evidence",
           "pipeline.inputs.photos", "pipeline.inputs.linkscsv", "pipeline.consistency.termination",
           "pipeline.consistency.evidence", "pipeline.fusion.robot", "pipeline.fusion.robot_loops",
           "pipeline.team.robot",
           "pipeline.transport.zenoh_transport", "pipeline.commands.robot", "pipeline.__main__")


def _robot(team_path: str, i: int, log_path: str, zygote_pid: int,
           launched_at: str | None = None) -> None:
    """The child: robot ``i``, its output in its log; never returns. It dies with the zygote
    (``zygote_pid``), even one that died before the child ran
    (:func:`pipeline.team.launcher.die_with_parent`). ``launched_at``: when its team was
    launched (a serving zygote's robots; otherwise the zygote's environment says it)."""
    code = 1
    try:
        if launched_at is not None:
            from pipeline.team.teamfile import LAUNCHED_AT_ENV

            os.environ[LAUNCHED_AT_ENV] = launched_at
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


def _preload() -> None:
    import importlib

    for name in PRELOAD:
        importlib.import_module(name)


def serve() -> int:
    """``python -m pipeline.team.zygote --serve``: fork the robots of every team named on the
    standard input (one JSON line each), until the input closes and every robot ended."""
    _preload()
    from pipeline.team.teamfile import load_team

    wake_r, wake_w = os.pipe()
    os.set_blocking(wake_w, False)
    signal.signal(signal.SIGCHLD, lambda *_: None)
    signal.set_wakeup_fd(wake_w)
    children: dict[int, tuple[str, int]] = {}
    me = os.getpid()
    pending, open_input = b"", True

    def reap() -> None:
        while children:
            try:
                pid, status = os.waitpid(-1, os.WNOHANG)
            except ChildProcessError:
                return
            if pid == 0:
                return
            who = children.pop(pid, None)
            if who is not None:
                print(f"exit {who[0]} {who[1]} {os.waitstatus_to_exitcode(status)}", flush=True)

    while open_input or children:
        ready = select.select([0, wake_r] if open_input else [wake_r], [], [])[0]
        if wake_r in ready:
            os.read(wake_r, 4096)
        reap()
        if 0 not in ready:
            continue
        chunk = os.read(0, 65536)
        if not chunk:
            open_input = False
            continue
        pending += chunk
        *lines, pending = pending.split(b"\n")
        for line in lines:
            if not line.strip():
                continue
            job = json.loads(line)
            tag, workdir = str(job["tag"]), job["workdir"]
            team = load_team(job["team"])
            for i in range(team.n):
                sys.stdout.flush()
                sys.stderr.flush()
                pid = os.fork()
                if pid == 0:
                    signal.set_wakeup_fd(-1)
                    signal.signal(signal.SIGCHLD, signal.SIG_DFL)
                    for fd in (wake_r, wake_w):
                        os.close(fd)
                    devnull = os.open(os.devnull, os.O_RDONLY)  # not the zygote's input
                    os.dup2(devnull, 0)
                    os.close(devnull)
                    _robot(job["team"], i, os.path.join(workdir, f"robot{i}.log"), me,
                           str(job["launched_at"]))
                children[pid] = (tag, i)
                print(f"pid {tag} {i} {pid}", flush=True)
    return 0


def main(argv: list[str] | None = None) -> int:
    """``python -m pipeline.team.zygote TEAM.json WORKDIR`` (one team), or ``--serve``
    (:func:`serve`)."""
    argv = list(argv if argv is not None else sys.argv[1:])
    if argv[:1] == ["--serve"]:
        return serve()
    team_path, workdir = argv[:2]
    _preload()
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
