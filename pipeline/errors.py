"""User-facing errors: the CLI prints these without a traceback (exit code 2)."""


class InputError(ValueError):
    """Bad user input. The message names the offending value and says what to do."""


def one_line(text: str) -> str:
    """``text`` with its line breaks and other characters that print nothing written as
    escapes (``\\n``, ``\\t``, ``\\u200b``): every error and warning is one line on stderr
    (README, "Errors you can meet"), and a file name a message quotes may hold a line break
    ('new\\nline.jpg' split a warning over two lines)."""
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii")
                   for c in text)


class TeamError(RuntimeError):
    """A team of robot processes did not finish: a robot never started, failed or hung (the
    message names it)."""


def listed(items, limit: int = 5, last: str = " and ") -> str:
    """``items`` for a one-line message: ``"3"``, ``"3 and 7"``, ``"3, 7 and 9"`` (``last``
    before the last item; ``", "`` for a plain list), or past ``limit`` the first ``limit``
    and how many more (``"3, 7, 9, 12, 15 and 3 more"``): a message about several robots or
    files names every one a user can act on, in one line."""
    shown = [str(x) for x in items]
    if len(shown) > limit:
        return f"{', '.join(shown[:limit])} and {len(shown) - limit} more"
    if len(shown) <= 1:
        return "".join(shown)
    return f"{', '.join(shown[:-1])}{last}{shown[-1]}"


def processes_lost(names) -> str:
    """``"the robot process of image N was lost"``, or for several images
    ``"the robot processes of images N, M and K were lost"`` (:func:`listed`): the start of
    a message about robot processes lost, naming every one (``names``: formatted already)."""
    names = list(names)
    if len(names) == 1:
        return f"the robot process of image {names[0]} was lost"
    return f"the robot processes of images {listed(names)} were lost"


class RobotsLost(TeamError):
    """Robots of a team were lost (their process ended or went silent) before it finished.

    ``cameras``: the lost robots, as the team's cameras (its callers' numbering); ``stats``:
    what the team that lost them spent (``messages``, ``bytes``, ``rounds``), where known."""

    def __init__(self, message: str, cameras, stats: dict | None = None):
        super().__init__(message)
        self.cameras = sorted(int(c) for c in cameras)
        self.stats = dict(stats or {})


def die_with_parent(parent_pid: int | None = None) -> None:
    """Ask the kernel to kill this process when its parent dies (Linux's
    ``PR_SET_PDEATHSIG``, SIGKILL): a child that must not outlive the command that started it
    (a robot, the robots' zygote, a forked feature worker); elsewhere nothing happens, and the
    child ends when its pipe to the parent closes, as before.

    The request holds only from when it is made: a parent that died between the fork and the
    ``prctl`` (a loaded machine may not run the child for a while) has already handed the child
    to another process, and no signal would come. So the child compares its parent with
    ``parent_pid`` (the forking process's pid, taken before the fork) once the request is in,
    and ends at once (exit 1) when they differ."""
    import ctypes
    import os
    import signal

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGKILL, 0, 0, 0)  # PR_SET_PDEATHSIG
    except (AttributeError, OSError):
        return
    if parent_pid is not None and os.getppid() != parent_pid:
        os._exit(1)


_interrupt_arrived = False  # set by the SIGINT handler of exit_quietly_on_interrupt


def _on_interrupt(signum, frame) -> None:
    """The SIGINT handler of a program of the project: Python's own (raise
    KeyboardInterrupt), which also records that a Ctrl-C arrived. A C extension interrupted
    while it loads may drop the KeyboardInterrupt and raise an unrelated error with no link to
    it (NumPy: ``ImportError: PyCapsule_Import could not import module "datetime"``); the
    record still tells :func:`caused_by_interrupt` why. Python may also drop the exception
    altogether (a handler that runs within a call whose error it clears); the record then
    tells :func:`run_interruptibly` that the command was interrupted."""
    global _interrupt_arrived
    _interrupt_arrived = True
    raise KeyboardInterrupt


def caused_by_interrupt(exc: BaseException | None) -> bool:
    """``exc`` is a KeyboardInterrupt, or an error raised because of one (a C++ extension
    interrupted while it loads reports an ImportError, which its package may turn into
    another error: pycolmap's "Cannot import the C++ backend"), or any error once a Ctrl-C has
    arrived in a program that records it (:func:`exit_quietly_on_interrupt`): the user asked
    the program to stop, and a library may have lost the KeyboardInterrupt on the way."""
    if exc is not None and _interrupt_arrived:
        return True
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False


class Terminated(SystemExit):
    """A SIGTERM (``kill PID``, ``timeout``) or a SIGHUP (the terminal closed) arrived: raised
    by the handler of :func:`clean_up_on_terminate` and by the team launcher's, so that every
    ``finally`` and ``with`` block runs on the way out (temporary folders, staging folders,
    the run folder's lock, robot processes) as on a Ctrl-C. Its exit status is 128 + the
    signal's number (143 for SIGTERM)."""

    def __init__(self, signum: int | None = None) -> None:
        import signal

        super().__init__(128 + int(signal.SIGTERM if signum is None else signum))


#: the signal :func:`_on_terminate` took, if any (while :func:`run_interruptibly` runs)
_terminate_arrived: int | None = None


def _on_terminate(signum, frame) -> None:
    """The SIGTERM/SIGHUP handler: raise :class:`Terminated`, and record the signal. Python
    drops the exception of a handler that runs within some of its own calls (a hook around
    a fork, a method it calls from C and whose error it clears: seen while a module defined
    a ``Callable[...]`` alias); the record still tells :func:`run_interruptibly`."""
    global _terminate_arrived
    _terminate_arrived = int(signum)
    raise Terminated(signum)


def clean_up_on_terminate() -> None:
    """Make a SIGTERM or a SIGHUP end the program as a Ctrl-C does, through its clean-up
    (:class:`Terminated`, exit status 143 or 129, one line ``terminated: … stopped …``)
    instead of at once with every temporary folder (``fm-team-*``, ``colmap-read-*``),
    staging folder and lock left behind. Only in the main thread, and not where the signal
    is ignored (``nohup``) or already handled."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return
    for sig in (signal.SIGTERM, signal.SIGHUP):
        if signal.getsignal(sig) == signal.SIG_DFL:
            signal.signal(sig, _on_terminate)


def report_interrupt(command: str, how: str = "interrupted", code: int = 130) -> int:
    """One line on stderr saying ``command`` was stopped by a Ctrl-C (naming the outputs
    already in place, if any); the exit status of an interrupted command, 130. With ``how``
    ``"terminated"`` and ``code``: stopped by a SIGTERM or a SIGHUP."""
    import sys

    done = []
    if "pipeline.runfolder" in sys.modules:  # else nothing can have been put in place
        done = sys.modules["pipeline.runfolder"].outputs_in_place()
    if done:  # too late to keep them: say which are there, written in full
        names = ", ".join(repr(str(p)) for p in done[:4]) + (", …" if len(done) > 4 else "")
        print(f"{how}: {command} stopped; already in place, complete: {names}",
              file=sys.stderr)
    else:
        print(f"{how}: {command} stopped, nothing was written or replaced",
              file=sys.stderr)
    return code


def _last_word(program: str, exc_type, exc, tb) -> None:
    """``program``'s last word on an exception nothing caught: a Ctrl-C (however early)
    ends with one line and exit 130, never a traceback or a death by signal."""
    import os
    import sys

    if caused_by_interrupt(exc):
        report_interrupt(program)
        try:
            sys.stderr.flush()
        finally:
            os._exit(130)
    sys.__excepthook__(exc_type, exc, tb)


def exit_quietly_on_interrupt(program: str) -> None:
    """Make a Ctrl-C that escapes ``program``'s main, however early (while its libraries
    load), end it as this program's does: one line naming ``program``, exit 130. For the
    other programs of the project (``python -m viz.saved_run``), before their imports."""
    import signal
    import sys
    import threading

    sys.excepthook = lambda exc_type, exc, tb: _last_word(program, exc_type, exc, tb)
    if (threading.current_thread() is threading.main_thread()
            and signal.getsignal(signal.SIGINT) is signal.default_int_handler):
        signal.signal(signal.SIGINT, _on_interrupt)  # not where SIGINT is ignored (nohup, &)


def _bench_name(path: str) -> str:
    from pathlib import Path

    return f"bench/{Path(path).name}"


def one_line_interrupts(module: str, path: str) -> None:
    """Called by a bench with its ``__name__`` and ``__file__`` before its libraries load: run
    as a program, a Ctrl-C while they load ends as one in its main does
    (:func:`one_line_errors`): one line ``interrupted: bench/NAME.py stopped …``, exit 130.
    Imported (by another bench, by the tests), it changes nothing."""
    if module == "__main__":
        exit_quietly_on_interrupt(_bench_name(path))


def one_line_errors(main):
    """A bench's ``main`` (or its entry point) ending as the command line does: an
    :class:`InputError` as one line ``error: …`` on stderr, exit status 2; a Ctrl-C as one
    line ``interrupted: bench/NAME.py stopped …``, exit status 130; no traceback."""
    import functools
    import sys

    name = _bench_name(main.__code__.co_filename)

    @functools.wraps(main)
    def wrapped(*args, **kwargs) -> int:
        try:
            return run_interruptibly(name, lambda: main(*args, **kwargs))
        except InputError as exc:
            print(f"error: {one_line(str(exc))}", file=sys.stderr)
            return 2
    return wrapped


def run_interruptibly(command: str, run) -> int:
    """``run()``'s exit code; a Ctrl-C while it runs (also one a library turned into another
    exception) ends it with :func:`report_interrupt`'s line and exit code 130; a SIGTERM or a
    SIGHUP (:func:`clean_up_on_terminate`) with the line ``terminated: …`` and 128 + the
    signal. Either, also one whose exception was dropped on the way (Python drops what a
    handler raises within some of its own calls; the Ctrl-C is known from the record of
    :func:`exit_quietly_on_interrupt`'s handler): the command then ran to its end, and the line
    names its outputs, all in place and complete."""
    global _terminate_arrived, _interrupt_arrived
    _terminate_arrived = None
    _interrupt_arrived = False
    try:
        code = run()
    except KeyboardInterrupt:
        return report_interrupt(command)
    except Terminated as exc:
        return report_interrupt(command, "terminated", exc.code)
    except Exception as exc:
        if _terminate_arrived is not None:
            return report_interrupt(command, "terminated", 128 + _terminate_arrived)
        if caused_by_interrupt(exc):  # e.g. while a library's C++ part was loading
            return report_interrupt(command)
        raise
    if _terminate_arrived is not None:
        return report_interrupt(command, "terminated", 128 + _terminate_arrived)
    if _interrupt_arrived:  # a Ctrl-C whose KeyboardInterrupt was dropped on the way
        return report_interrupt(command)
    return code


class StageStalledError(RuntimeError):
    """A distributed stage did not end within the bound of rounds it is proven to end in
    (the message names the robot or stage and the bound). A correct run never reaches it:
    the inputs break an assumption no check caught, or the stage has a defect. The command
    line reports it as one line (exit code 2)."""
