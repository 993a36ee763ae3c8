"""Open a run's recording in Rerun: ``python -m viz.view [RUN_DIR | FILE.rrd]`` (``make view``).

Without a path it opens the newest ``runs/**/recording.rrd``. On a machine with a display it
starts the native viewer; without one (:func:`has_display`: on Linux no ``DISPLAY`` /
``WAYLAND_DISPLAY``, on macOS and Windows a session over SSH) it serves the web viewer (``rerun FILE --web-viewer``) and prints the URL to open, with the SSH
port forwarding to reach it from another machine. ``--web`` / ``--native`` force either.

The web viewer's page takes its data source only from its ``?url=`` parameter (the gRPC
proxy that serves the recording): the printed URL carries it (:func:`web_url`); the bare
``http://localhost:9090`` opens an empty viewer. ``python -m viz.browser`` checks the URL in
headless Chromium.
"""

from __future__ import annotations

import argparse
import os
import re
import shlex
import shutil
import subprocess
import sys
import threading
from pathlib import Path

__all__ = ["check_recording", "find_recording", "names_shown", "viewer_command", "web_url", "main",
           "rerun_executable", "spawn_viewer"]

WEB_PORT = 9090
#: the help of the recording to open (this command's and :mod:`viz.browser`'s)
TARGET_HELP = ("a run folder (its recording.rrd) or a .rrd file (default: the newest "
               "recording.rrd under runs/)")
GRPC_PORT = 9876
#: the address the web viewer serves on (:func:`viewer_command`)
LOOPBACK = "127.0.0.1"


#: what a run-landmarks folder is, for a reader asking it for a recording
LANDMARKS_RUN_NOTE = ("a run-landmarks run folder (report.json, links.csv): run-landmarks "
                      "writes no recording (labelled landmarks come without camera poses); "
                      "read its report.json and links.csv")


def landmarks_run(folder: Path) -> bool:
    """Whether ``folder`` holds the report of a ``run-landmarks`` run (its
    ``feature_landmarks``)."""
    import json

    if not (folder / "report.json").is_file():  # a FIFO would block the read
        return False
    try:
        report = json.loads((folder / "report.json").read_text())
    except (OSError, UnicodeDecodeError, ValueError):
        return False
    return isinstance(report, dict) and "feature_landmarks" in report


#: a run's staging folder beside its run folder NAME (pipeline.runfolder)
STAGING_NAME = re.compile(r"\.(.+)\.tmp-[^/]*")


def staging_note(path: Path) -> str | None:
    """What ``path`` is when it is a run's staging folder ``.NAME.tmp-*`` (it holds the run
    marker) or a file in one, and what to open instead; else None."""
    from pipeline.outputs import RUN_MARKER

    for folder in (path, path.parent):
        m = STAGING_NAME.fullmatch(folder.name)
        if m and folder.is_dir() and (folder / RUN_MARKER).is_file():
            run = folder.parent / m.group(1)
            return (f"{'' if folder is path else 'a file in '}the staging folder of the run "
                    f"folder {run}: a run writes there and puts it in place as {run.name} when "
                    f"done (one killed left it; the next run into {run.name} removes it); give "
                    f"{run}")
    return None


def find_recording(target: str | os.PathLike | None, runs: Path = Path("runs")) -> Path:
    """The ``.rrd`` to open: ``target`` itself, ``target/recording.rrd`` (or the only ``.rrd``
    in a folder, hidden ones left out), or the newest ``recording.rrd`` under ``runs`` outside
    hidden folders (a run's staging folder holds a recording before the run is in place, or
    after it failed).

    Raises
    ------
    FileNotFoundError
        Nothing to open (with what to run first).
    """
    from pipeline.progress import counted

    if target:
        p = Path(target)
        staging = staging_note(p) if p.exists() else None
        if staging:
            raise FileNotFoundError(f"{p}: {staging}")
        if p.is_file():
            if p.suffix != ".rrd":
                beside = p.with_suffix(".rrd")  # clean-db / clean-h5 write OUT.rrd by OUT
                hint = (f"; its recording is {beside}" if beside.is_file() else
                        "; give a run folder or its recording.rrd")
                raise FileNotFoundError(f"{p}: not a Rerun recording (.rrd){hint}")
            return p
        if p.is_dir():
            if (p / "recording.rrd").is_file():
                return p / "recording.rrd"
            # a hidden .rrd is no output: the temporary file of one being written, or left
            # by a command killed before putting its outputs in place (clean-db, clean-h5)
            found = sorted(q for q in p.glob("*.rrd") if not q.name.startswith("."))
            if len(found) == 1:
                return found[0]
            if found:  # several outputs of clean-db / clean-h5 in one folder
                raise FileNotFoundError(f"{p}: {len(found)} recordings in this folder "
                                        f"({names_shown(found)}): give the one to open")
            # a hidden folder is no run (the staging folder of a run killed before its
            # folder was put in place), as for the newest recording below
            runs_in = sorted(q.parent for q in p.glob("*/recording.rrd")
                             if not q.parent.name.startswith("."))
            if runs_in:  # the parent of run folders, e.g. run-formations' --out
                raise FileNotFoundError(f"{p}: a folder of {counted(len(runs_in), 'run')} "
                                        f"({names_shown(runs_in)}): give the run to open")
            if landmarks_run(p):
                raise FileNotFoundError(f"{p}: {LANDMARKS_RUN_NOTE}")
            raise FileNotFoundError(f"{p}: no recording.rrd in this folder; {_no_recording(p)}")
        raise FileNotFoundError(f"{p}: no such run folder or .rrd file")
    # a hidden folder is no run: e.g. the staging folder of a run still writing, or of one
    # killed before its folder was put in place (pipeline.runfolder.atomic_run_folder)
    found = sorted((q for q in runs.glob("**/recording.rrd")
                    if not any(part.startswith(".") for part in q.relative_to(runs).parts)),
                   key=lambda q: q.stat().st_mtime)
    if not found:
        raise FileNotFoundError(f"no recording under {runs}/ yet: run 'make run-formation' first")
    return found[-1]


def _no_recording(folder: Path) -> str:
    """What to do about a folder without a recording: a run folder written with
    ``--no-rerun`` gets one from :mod:`viz.saved_run`, an online one only from its run; any
    other folder (``resolve``'s outputs, a killed run's staging folder) is no run folder."""
    if (folder / "link_steps.csv").is_file() and (folder / "images.csv").is_file():
        return ("an online run folder written with --no-rerun: its recording, on the step "
                "timeline, is written by the run itself; run it again without --no-rerun")
    if all((folder / name).is_file() for name in ("report.json", "links.csv")) and \
            (folder / "sparse").is_dir():
        return ("a run folder written with --no-rerun: write its recording with python -m "
                f"viz.saved_run {shlex.quote(str(folder))}, then open it")
    return ("not a run folder (a run-formation or run-images run folder holds report.json, "
            "links.csv and sparse/; resolve writes no recording): give the run folder (--out) "
            "of a run-formation or run-images run")


#: how every ``.rrd`` file begins: Rerun's file header magic, ``RRF`` and its format version
RRD_MAGIC = re.compile(rb"RRF[0-9]")


def check_recording(path: Path) -> Path:
    """``path`` if it begins as a Rerun recording does (:data:`RRD_MAGIC`) and ends with the
    footer Rerun writes when it closes one.

    The viewer opens any file it is given and, on one that is not a recording, serves an
    empty viewer with no error; on a recording cut short (a copy or download not finished, a
    full disk) it shows the part before the cut, without the layout or the report, again with
    no error: the file is checked before it is handed over.

    Raises
    ------
    FileNotFoundError
        ``path`` is not a regular file, does not read, is empty, another kind of file or a
        recording cut short (naming it).
    """
    if not Path(path).is_file():  # a FIFO would block the read (and the viewer) for ever
        raise FileNotFoundError(f"{path}: not a regular file (a folder, FIFO, device or a "
                                "symbolic link leading nowhere); give a run folder or its "
                                "recording.rrd")
    try:
        with open(path, "rb") as f:
            head = f.read(4)
    except OSError as exc:
        raise FileNotFoundError(f"{path}: cannot be read ({exc.strerror})") from None
    if not RRD_MAGIC.fullmatch(head):
        what = "an empty file" if not head else "not a Rerun recording (it lacks the .rrd header)"
        raise FileNotFoundError(f"{path}: {what}; give a run folder, or a .rrd written by a "
                                "run or by python -m viz.saved_run")
    from rerun_bindings import check_for_rrd_footer

    if not check_for_rrd_footer(str(path)):  # every recording this project writes has one
        raise FileNotFoundError(f"{path}: a recording cut short (it ends before the footer "
                                "that closes a recording: a copy or download not finished, a "
                                "full disk); copy it again, or write it anew: run again the "
                                "command that wrote it, or python -m viz.saved_run RUN_DIR "
                                "--out NEW.rrd for a run folder")
    return path


def names_shown(paths: list[Path], shown: int = 4) -> str:
    """``paths`` by name, comma-separated, or the first ``shown`` and how many more
    (:func:`pipeline.errors.listed`)."""
    from pipeline.errors import listed

    return listed([repr(q.name) for q in paths], shown, last=", ")


def has_display(env=None, platform: str | None = None) -> bool:
    """Whether the native viewer can open a window here: on macOS and Windows, unless the
    session is a remote shell (``SSH_CONNECTION`` / ``SSH_TTY``); elsewhere (Linux, BSD),
    when ``DISPLAY`` or ``WAYLAND_DISPLAY`` names a display."""
    env = os.environ if env is None else env
    platform = sys.platform if platform is None else platform
    if platform.startswith(("darwin", "win32", "cygwin")):  # no DISPLAY: a window server
        return not (env.get("SSH_CONNECTION") or env.get("SSH_TTY"))
    return bool(env.get("DISPLAY") or env.get("WAYLAND_DISPLAY"))


def rerun_executable() -> str:
    """The ``rerun`` viewer of this environment (beside its Python), else on ``PATH``."""
    return shutil.which("rerun", path=str(Path(sys.executable).parent)) \
        or shutil.which("rerun") or "rerun"


def _listening(port: int, host: str = LOOPBACK) -> bool:
    import socket

    with socket.socket() as s:
        s.settimeout(0.2)
        return s.connect_ex((host, int(port))) == 0


def spawn_viewer(port: int = GRPC_PORT, wait_s: float = 10.0) -> str:
    """Start the native viewer for a live run (``run-images --spawn``), as ``rr.spawn`` does
    but bound to this machine's loopback address: ``rr.spawn`` has no bind option, and the
    viewer's server would take connections (and serve the run's photographs) on every
    interface. A viewer already listening on ``port`` takes the stream instead, as with
    ``rr.spawn``. Waits up to ``wait_s`` for it to listen; returns the gRPC URL to stream to.
    """
    url = f"rerun+http://{LOOPBACK}:{int(port)}/proxy"
    if _listening(port):
        return url
    subprocess.Popen([rerun_executable(), "--port", str(int(port)), "--bind", LOOPBACK,
                      "--memory-limit", "75%",  # rr.spawn's default
                      "--expect-data-soon"], start_new_session=True,
                     stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                     stderr=subprocess.DEVNULL)
    import time

    end = time.monotonic() + wait_s
    while time.monotonic() < end and not _listening(port):
        time.sleep(0.05)
    return url


def viewer_command(path: Path, web: bool, port: int = WEB_PORT,
                   grpc_port: int = GRPC_PORT) -> list[str]:
    """The ``rerun`` command line that opens ``path`` natively or in the web viewer (page on
    ``port``, the recording served by the gRPC proxy on ``grpc_port``), on this machine's
    loopback address only: Rerun's default, every interface, would serve the recording to
    anyone who can reach the machine; from another machine the printed SSH port forwarding
    reaches it. The native viewer serves too (its local viewer server, on 9876 or a free
    port, which takes the logging SDK's connections): bound to loopback as well."""
    exe = rerun_executable()
    arg = str(path)
    cmd = [exe, os.path.join(".", arg) if arg.startswith("-") else arg]  # not an option of rerun's
    if web:
        cmd += ["--web-viewer", "--web-viewer-port", str(port), "--port", str(grpc_port)]
    return cmd + ["--bind", LOOPBACK]


def web_url(port: int = WEB_PORT, grpc_port: int = GRPC_PORT, host: str = "localhost") -> str:
    """The URL that opens the served recording in the web viewer: the page, with the gRPC
    proxy it must read as its ``url`` parameter (as Rerun's own log line gives it).

    Examples
    --------
    >>> web_url()
    'http://localhost:9090/?url=rerun%2Bhttp%3A%2F%2Flocalhost%3A9876%2Fproxy'
    """
    from urllib.parse import quote

    return f"http://{host}:{port}/?url=" + quote(f"rerun+http://{host}:{grpc_port}/proxy",
                                                 safe="")


def _bad_ports(port: int, grpc_port: int) -> str | None:
    """Why the web viewer cannot serve on these ports (the URL would name them), or None."""
    for flag, p in (("--port", port), ("--grpc-port", grpc_port)):
        if not 1 <= p <= 65535:
            return f"{flag} {p}: give a TCP port from 1 to 65535"
    if port == grpc_port:
        return (f"--port and --grpc-port are both {port}: the page and the recording need a "
                f"port each, e.g. --port {port} --grpc-port {port + 1 if port < 65535 else 1}")
    return None


def _busy_port(port: int, grpc_port: int) -> str | None:
    """Why the web viewer cannot serve on these ports now: one of them is taken on
    :data:`LOOPBACK` (another viewer still serving, or another program), or None. Rerun would
    fail after the URL is printed, naming the page's port but not the recording's."""
    import errno
    import socket

    for flag, p in (("--port", port), ("--grpc-port", grpc_port)):
        with socket.socket() as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as a server binds
            try:
                s.bind((LOOPBACK, p))
            except OSError as exc:
                if exc.errno != errno.EADDRINUSE:
                    continue  # rerun says why (e.g. a port below 1024 without root)
                return (f"{flag} {p}: the port is in use on {LOOPBACK} (another viewer still "
                        "serving, e.g. an earlier python -m viz.view --web, or another "
                        f"program); stop it, or serve on a free one: python -m viz.view RUN {flag} N")
    return None


def parse_with_recording(ap: argparse.ArgumentParser, argv) -> tuple[argparse.Namespace,
                                                                      Path | None]:
    """``ap``'s arguments (its ``target`` a run folder or ``.rrd``) and the recording to open,
    or ``None`` after printing why there is none."""
    args = ap.parse_args(argv)
    try:
        return args, check_recording(find_recording(args.target))
    except FileNotFoundError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return args, None


def say(text: str) -> None:
    """Print ``text`` to stdout at once. A reader that stopped reading (``| head -1``) ends
    the printing, not the command: the rest of stdout, the viewer's included, goes to
    /dev/null."""
    try:
        print(text, flush=True)
    except BrokenPipeError:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m viz.view", description=__doc__.split("\n\n")[0])
    ap.add_argument("target", nargs="?", default=None, metavar="RUN_DIR|FILE.rrd",
                    help=TARGET_HELP)
    mode = ap.add_mutually_exclusive_group()
    mode.add_argument("--web", action="store_true",
                      help="serve the web viewer and print its URL (the default without a "
                           "display)")
    mode.add_argument("--native", action="store_true",
                      help="start the native viewer (the default on a machine with a display)")
    ap.add_argument("--port", type=int, default=WEB_PORT, help="web viewer port (default 9090)")
    ap.add_argument("--grpc-port", type=int, default=GRPC_PORT,
                    help="port of the gRPC proxy that serves the recording (default 9876)")
    ap.add_argument("--dry-run", action="store_true", help="print the command, do not run it")
    from pipeline.__main__ import paths_printable

    paths_printable()
    args, path = parse_with_recording(ap, argv)
    if path is None:
        return 2
    web = args.web or (not args.native and not has_display())
    bad = _bad_ports(args.port, args.grpc_port) if web else None
    if web and not bad and not args.dry_run:
        bad = _busy_port(args.port, args.grpc_port)
    if bad:
        print(f"error: {bad}", file=sys.stderr)
        return 2
    if not web and not args.dry_run and sys.platform.startswith("linux") and not has_display():
        # the native viewer would fail with its own multi-line log and exit status 1
        print("error: --native needs a display (DISPLAY / WAYLAND_DISPLAY is not set): drop "
              "--native to serve the web viewer, or run it where there is a display",
              file=sys.stderr)
        return 2
    cmd = viewer_command(path, web, args.port, args.grpc_port)
    say(f"opening {path}")
    if web:
        say(f"web viewer: {web_url(args.port, args.grpc_port)}\n(from another machine: "
             f"ssh -L {args.port}:localhost:{args.port} -L {args.grpc_port}:localhost:"
             f"{args.grpc_port} HOST, then open that URL); Ctrl-C stops it")
    if args.dry_run:
        say(shlex.join(cmd))  # a path with a space or a quote stays one argument
        return 0
    return run_viewer(cmd)


class _Stopped(Exception):
    """This process got SIGTERM or SIGHUP (``kill PID``, a closed terminal)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum


def run_viewer(cmd: list[str]) -> int:
    """Run the viewer ``cmd`` until it ends, and return its exit status. A Ctrl-C ends both
    (status 0); a SIGTERM or SIGHUP to this process (``kill PID``, a closed terminal) stops the
    viewer before this process ends with ``128 + signal``: left running, its server would
    hold the ports of the next ``python -m viz.view --web``.

    The viewer runs in its own process group and is stopped as a group: the ``rerun`` command
    of the Python package is a wrapper that starts the viewer binary as its child, which a
    signal to the wrapper alone left running."""
    import signal

    proc = subprocess.Popen(cmd, process_group=0)

    def stop(signum, _frame):
        raise _Stopped(signum)

    handled = (signal.SIGTERM, signal.SIGHUP)
    old = {s: signal.signal(s, stop) for s in handled} \
        if threading.current_thread() is threading.main_thread() else {}
    try:
        return proc.wait()
    except KeyboardInterrupt:
        return 0
    except _Stopped as exc:
        return 128 + exc.signum
    finally:
        for s, h in old.items():
            signal.signal(s, h)
        if proc.poll() is None:  # not reaped: its pid still names its group
            _signal_group(proc.pid, signal.SIGTERM)
            try:
                proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                _signal_group(proc.pid, signal.SIGKILL)
                proc.wait()


def _signal_group(pgid: int, sig: int) -> None:
    try:
        os.killpg(pgid, sig)
    except ProcessLookupError:  # every process of it has ended
        pass


if __name__ == "__main__":
    sys.exit(main())
