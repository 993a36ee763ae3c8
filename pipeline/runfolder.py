"""Atomic run folders and output files (docs/DESIGN.md "Run outputs — a contract").

A run writes into a staging folder ``.NAME.tmp-*`` beside ``NAME``; only when everything is
written is it put in place. Guarantees:

- **Only our own run folders are replaced.** Every run folder carries the marker file
  :data:`~pipeline.outputs.RUN_MARKER`, which lists what the run wrote;
  :func:`~pipeline.outputs.check_run_folder` refuses any other existing non-empty folder, a run
  folder holding anything a user added or changed, a file, a symbolic link, ``/``, the
  current folder or its parents, and a folder holding an input.
- **Only our own sibling entries are touched.** Beside ``NAME`` a run uses ``.NAME.tmp-R``
  (staging), ``.NAME.old-R`` (the previous run, see below), ``.NAME.lock`` and
  ``.NAME.lock-R`` (``R`` a random part). Each one carries, from the instant it appears under
  its name, a digest of its own inode (:func:`~pipeline.outputs.ownership_proof`): in the
  folder's marker, in the lock file's first line. An entry of such a name without it (a
  user's folder, file or symbolic link) is never removed, renamed or written through:
  a foreign ``.NAME.lock`` stops the run with an error naming it; a foreign
  ``.NAME.tmp-*`` / ``.NAME.old-*`` is left alone. Entries are opened with ``O_NOFOLLOW`` and
  created with ``O_EXCL`` (or renamed into place without replacing, ``RENAME_NOREPLACE``).
- **One writer per run folder.** A run holds an exclusive ``fcntl.flock`` on ``.NAME.lock``
  (holding its pid) from :func:`claim_run_folder` (the start of a command) until its folder
  is in place. The lock file is written and locked under a random name and then linked to
  ``.NAME.lock`` without replacing anything, so it is never seen half-written. A second run
  into the same ``--out`` does not wait: it stops at once with an InputError naming the pid
  that holds the folder.
- **Either the old or the new run is in place at every instant.** The staging folder and the
  old run are swapped in one ``renameat2(RENAME_EXCHANGE)`` system call (Linux); where the file
  system lacks it, the old run is renamed ``.NAME.old-R`` and the new one renamed into place
  (two steps). A run killed between those two steps leaves ``NAME`` missing and
  ``.NAME.old-R`` present: the next run into ``NAME`` restores it when it takes the lock.
- **No leftovers.** Under the lock no other run can be staging ``NAME``, so every
  ``.NAME.tmp-*`` and ``.NAME.old-*`` of ours found then belongs to a dead run and is removed
  (one holding anything a user added is left alone). The lock file is removed by its holder
  while still locked; a run that locked a file already removed retries on the new one.

Several run folders of one command (``run-formations``: one per formation, and its summary
files) are put in place together (:func:`publish_together`): each is staged as above, none
replaces its ``NAME`` until all are written, and the swaps then run with SIGINT and SIGTERM
held, so an interrupt or an error before that leaves every previous run as it was.

Output files (:func:`atomic_file`, :class:`OutputFiles`) are written to a temporary name and
renamed into place; a command's outputs are all written before any is put in place, and one
that may not replace an existing file is put in place without replacing (an output created
by someone else while the command worked is kept, and the command says so).
"""

from __future__ import annotations

import ctypes
import errno
import fcntl
import hashlib
import json
import os
import re
import secrets
import shutil
import signal
import stat
import sys
import tempfile
import threading
from contextlib import ExitStack, contextmanager
from pathlib import Path

import numpy as np

from pipeline.errors import InputError
from pipeline.outputs import (
    RUN_MARKER,
    check_run_folder,
    own_folder,
    ownership_proof,
    refuse_unsafe_target,
    run_folder_problem,
    write_run_marker,
)

__all__ = ["OutputFiles", "outputs_in_place", "forget_outputs_in_place", "note_output_in_place",
           "atomic_file", "atomic_run_folder", "claim_run_folder", "output_path", "reading_run_folder",
           "staging_beside",
           "publish", "publish_mode", "publish_together", "write_json_atomic",
           "make_scratch_folder", "scratch_folder"]


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def publish_mode(path: str | os.PathLike, directory: bool) -> None:
    """Give a temp file/folder the mode a plain ``open``/``mkdir`` would have given it
    (``mkstemp``/``mkdtemp`` create them private, 0600/0700)."""
    os.chmod(path, (0o777 if directory else 0o666) & ~_umask())


def _json_default(obj):
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.floating):
        return float(obj)
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serializable: {type(obj).__name__}")


# ------------------------------------------------------------------------------ renames

_RENAME_NOREPLACE = 1
_RENAME_EXCHANGE = 2
_AT_FDCWD = -100


def _renameat2():
    try:
        fn = ctypes.CDLL(None, use_errno=True).renameat2
    except (AttributeError, OSError):
        return None
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    fn.restype = ctypes.c_int
    return fn


def _rename2(a: str | os.PathLike, b: str | os.PathLike, flags: int) -> bool:
    """``renameat2(a, b, flags)``; False where the system or the file system lacks it."""
    fn = _renameat2()
    if fn is None:
        return False
    if fn(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), flags) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.ENOSYS, errno.EINVAL, errno.ENOTSUP, errno.EPERM):
        return False
    raise OSError(err, os.strerror(err), str(b))


def _rename_noreplace(a: str | os.PathLike, b: str | os.PathLike) -> None:
    """Rename ``a`` to ``b``; FileExistsError if ``b`` exists (even as a dangling link)."""
    if _rename2(a, b, _RENAME_NOREPLACE):
        return
    if os.path.lexists(b):
        raise FileExistsError(errno.EEXIST, os.strerror(errno.EEXIST), str(b))
    os.rename(a, b)


def publish(tmp: str | os.PathLike, path: str | os.PathLike, replace: bool) -> None:
    """Put the finished file ``tmp`` at ``path`` in one step.

    With ``replace`` an existing ``path`` is replaced (``os.replace``); without, nothing is:
    FileExistsError if ``path`` exists, however it came there (an output made by someone else
    while the command worked is kept). A symbolic link at ``path`` is never followed.
    """
    if replace:
        os.replace(tmp, path)
        return
    if _rename2(tmp, path, _RENAME_NOREPLACE):
        return
    try:
        os.link(tmp, path)  # atomic, and fails on any existing entry
    except FileExistsError:
        raise
    except OSError:  # a file system without hard links
        _rename_noreplace(tmp, path)
        return
    os.unlink(tmp)


def _appeared(path: Path, flag: str) -> InputError:
    return InputError(f"{flag} {str(path)!r} was created by someone else while this command "
                      "worked; it is kept as it is and nothing was written there: pass "
                      "--overwrite to replace it, or choose a new name")


def _named(exc: OSError, path: Path) -> OSError:
    """``exc`` naming ``path`` when it names no file (a full disk, a file-size limit)."""
    if exc.filename is None and exc.errno is not None:
        return OSError(exc.errno, exc.strerror, str(path))
    return exc


@contextmanager
def atomic_file(path: str | os.PathLike, mode: str = "w", newline: str | None = None,
                replace: bool = True, flag: str = "output"):
    """Open a temporary file beside ``path``; on success it is put at ``path`` in one rename.

    On any error the temporary file is removed and ``path`` is left as it was. A ``path``
    that is a symbolic link, a folder or a special file (``/dev/null``, a FIFO) is refused
    (InputError) rather than replaced. Without ``replace`` an existing ``path`` is never
    replaced, even one that appeared while the file was written (InputError naming
    ``flag``). An error writing the file names ``path``.
    """
    path = Path(path)
    refuse_unsafe_target(path, flag)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = _new_part(path)
    try:
        try:
            with os.fdopen(fd, mode, newline=newline) as f:
                yield f
        except OSError as exc:
            raise _named(exc, path) from None
        publish_mode(tmp, directory=False)
        refuse_unsafe_target(path, flag)
        try:
            publish(tmp, path, replace)
        except FileExistsError:
            raise _appeared(path, flag) from None
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def write_json_atomic(path: str | os.PathLike, data, replace: bool = True,
                      flag: str = "output") -> Path:
    """Write ``data`` as indented JSON to ``path`` atomically (see :func:`atomic_file`)."""
    with atomic_file(path, replace=replace, flag=flag) as f:
        json.dump(data, f, indent=2, default=_json_default)
        f.write("\n")
    return Path(path)


class OutputFiles:
    """The output files of one command, written first and put in place together at the end.

    :meth:`path` gives a temporary file beside each output for any writer to fill (or replace
    atomically); leaving the ``with`` block normally puts every one in place
    (:func:`publish`, replacing existing files only with ``replace``, i.e. ``--overwrite``),
    with the mode a plain ``open`` gives (the umask). On any error, or an output that appeared
    meanwhile without ``replace``, none is left: the temporary files are removed, and so are
    the outputs this block had already put in place as new files.

    Example
    -------
    >>> import pathlib, tempfile
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> with OutputFiles(replace=False) as out:
    ...     _ = out.path(d / "a.csv", "--out").write_text("a")
    ...     _ = out.path(d / "b.json", "--report").write_text("{}")
    >>> sorted(p.name for p in d.iterdir())
    ['a.csv', 'b.json']
    """

    def __init__(self, replace: bool):
        self.replace = bool(replace)
        self._items: list[tuple[Path, Path, str]] = []

    def path(self, target: str | os.PathLike, flag: str = "output") -> Path:
        """A new empty temporary file beside ``target`` (kept extension), put at ``target``
        when the block ends."""
        target = Path(target)
        refuse_unsafe_target(target, flag)
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = _new_part(target)
        os.close(fd)
        self._items.append((tmp, target, flag))
        return tmp

    def __enter__(self) -> OutputFiles:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        try:
            if exc_type is None:
                self._commit()
            elif isinstance(exc, OSError) and exc.filename is not None:
                # an error writing a temporary file (or a writer's own temporary beside it)
                # names the output the user gave
                name = os.path.basename(os.fsdecode(exc.filename))
                for tmp, target, _ in self._items:
                    if name == tmp.name or name.startswith(f".{tmp.name}."):
                        raise OSError(exc.errno, exc.strerror, str(target)) from None
        finally:
            for tmp, _, _ in self._items:
                if os.path.lexists(tmp):
                    os.unlink(tmp)

    def _commit(self) -> None:
        # two commands putting outputs of the same names in place at once (``--overwrite``)
        # take turns: each one's outputs land together, never one's OUT.db beside the other's
        # OUT.links.csv
        with _folders_locked({tmp.parent for tmp, _, _ in self._items}):
            self._put_all_in_place()

    def _put_all_in_place(self) -> None:
        done: list[tuple[Path, tuple[int, int]]] = []
        try:
            for tmp, target, flag in self._items:
                if not tmp.is_file():
                    raise InputError(f"{flag} {str(target)!r}: its temporary file {str(tmp)!r} "
                                     "was removed while the command worked; nothing was written")
                publish_mode(tmp, directory=False)
                refuse_unsafe_target(target, flag)
                st = os.lstat(tmp)  # the file keeps its inode when put in place
                _put_in_place_so_far.append(target)  # before: an interrupt may end it there
                try:
                    publish(tmp, target, self.replace)
                except OSError as exc:
                    _put_in_place_so_far.remove(target)
                    if isinstance(exc, FileExistsError):
                        raise _appeared(target, flag) from None
                    raise _named(exc, target) from None
                done.append((target, (st.st_dev, st.st_ino)))
        except BaseException:
            if not self.replace:  # files this block created: leave none
                for target, ours in done:
                    _unlink_if_ours(target, ours)
                    _put_in_place_so_far.remove(target)
            raise


@contextmanager
def _folders_locked(folders):
    """Hold an exclusive ``flock`` on each of ``folders`` (in one order, so that two holders
    never wait on each other), waiting for another holder; a folder that cannot be locked
    (no permission to open it, a file system without locks) is passed over."""
    with ExitStack() as held:
        for folder in sorted({os.path.realpath(f) for f in folders}):
            try:
                fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
            except OSError:
                continue
            held.callback(os.close, fd)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX)
            except OSError:
                continue
        yield


def _unlink_if_ours(path: Path, ours: tuple[int, int]) -> None:
    """Remove ``path`` if it is still the file ``ours`` (device, inode) that this command put
    there: another command's output written there meanwhile (``--overwrite``) is kept."""
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return
    if (st.st_dev, st.st_ino) == ours:
        os.unlink(path)


# The temporary file of an output is ``.STEM.PID-START-R-D.partSUFFIX``: the process that
# writes it (pid and start time, so that a reused pid is told apart), a random part and a
# keyed digest of all that and of the machine's boot and pid namespace (:func:`_pid_space`),
# which a name a user gave, or a process of another machine or container, does not carry. A later command writing
# the same output removes those of processes no longer alive, with the files their writers
# made beside them (``.NAME.*``: a SQLite journal, a recording's own temporary file).

def _process_start(pid: int) -> str | None:
    """The start time of process ``pid`` (clock ticks since boot); None when there is none."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            stat_line = f.read().decode("ascii", errors="replace")
    except OSError:
        return None
    return stat_line.rsplit(")", 1)[-1].split()[19]  # field 22; the name may hold spaces


def _pid_space() -> str:
    """This boot of this machine and its process namespace: where a pid means one process (a
    folder shared over the network or with a container is written by others' pids too)."""
    try:
        with open("/proc/sys/kernel/random/boot_id") as f:
            boot = f.read().strip()
        return f"{boot} {os.readlink('/proc/self/ns/pid')}"
    except OSError:
        return ""


def _part_digest(target: Path, pid: str, start: str, rand: str) -> str:
    h = hashlib.blake2b(os.fsencode(f"{target.stem}|{target.suffix}|{pid}|{start}|{rand}|"
                                    f"{_pid_space()}"), digest_size=6, key=b"formation-match: temporary output file")
    return h.hexdigest()


def _part_name(target: Path, rand: str) -> str:
    pid = str(os.getpid())
    start = _process_start(os.getpid()) or "0"
    return (f".{target.stem}.{pid}-{start}-{rand}-{_part_digest(target, pid, start, rand)}"
            f".part{target.suffix}")


#: any temporary file of ours (:func:`_new_part`)
_ANY_PART = re.compile(r"\..+\.(\d+-\d+-[0-9a-f]{8}-[0-9a-f]{12}|[0-9a-f]{8})\.part.*")
#: the longest temporary name that leaves room for its writer's own files beside it (a
#: recording's ``.NAME.XXXXXXXX.tmp``, a database's ``NAME-journal``) under the usual 255 bytes
_PART_NAME_MAX = 240


def _new_part(target: Path) -> tuple[int, Path]:
    """A new temporary file for ``target`` beside it (open for writing, mode 0600), once the
    dead commands' ones are removed. For a ``target`` that is itself one of them (a JSON
    written into an output's temporary file) a short ``.TARGET.R``, removed with it; for a
    name too long to carry the process, the short ``.STEM.R.partSUFFIX`` (never removed)."""
    own = _ANY_PART.fullmatch(target.name) is not None
    if not own:
        _drop_dead_parts(target)
    while True:
        rand = secrets.token_hex(4)
        name = f".{target.name}.{rand}" if own else _part_name(target, rand)
        if len(os.fsencode(name)) > _PART_NAME_MAX and not own:
            name = f".{target.stem}.{rand}.part{target.suffix}"
        tmp = target.parent / name
        try:
            return os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o600), tmp
        except FileExistsError:
            continue


def _drop_dead_parts(target: Path) -> None:
    """Remove the temporary files of ``target`` left by commands killed while writing it
    (and what their writers made beside them); only names carrying their digest, only
    regular files, only where the system tells which processes live (``/proc``)."""
    if _process_start(os.getpid()) is None or not _pid_space():
        return
    part = re.compile(rf"\.{re.escape(target.stem)}\.(\d+)-(\d+)-([0-9a-f]{{8}})-([0-9a-f]{{12}})"
                      rf"\.part")
    try:
        entries = os.listdir(target.parent)
    except OSError:
        return
    for name in entries:
        m = part.match(name)
        if m is not None and name[m.end():] != target.suffix:
            m = None
        if m is None and name.startswith("."):  # a file a writer made beside one: .PART*
            m = part.match(name, 1)
            if m is not None and not name[m.end():].startswith("."):
                m = None
        if m is None:
            continue
        pid, start, rand, digest = m.groups()
        if digest != _part_digest(target, pid, start, rand) or _process_start(int(pid)) == start:
            continue
        path = target.parent / name
        try:
            if stat.S_ISREG(os.lstat(path).st_mode):
                os.unlink(path)
        except OSError:
            pass


# ------------------------------------------------------------------------------ scratch folders

# A command's private folders in the temporary folder (a team's TEAM.json and logs, a
# database's snapshot, a mapping's work) are ``PREFIX PID-START-D-R``: the process that made
# them (pid and start time), a keyed digest of those and of the machine's boot and pid
# namespace (:func:`_pid_space`), and mkdtemp's random part. The command removes its own on
# every way out it lives through; a process killed outright (kill -9, the OOM killer, a
# test's timeout) cannot, and the next folder of the same prefix made on this machine
# removes those of processes no longer alive.

_SCRATCH_RANDOM = "[a-z0-9_]{8}"  # tempfile's random part


def _scratch_digest(prefix: str, pid: str, start: str) -> str:
    h = hashlib.blake2b(os.fsencode(f"{prefix}|{pid}|{start}|{_pid_space()}"), digest_size=6,
                        key=b"formation-match: scratch folder")
    return h.hexdigest()


def _drop_dead_scratch(prefix: str, parent: Path) -> None:
    """Remove the folders ``PREFIX…`` of ours under ``parent`` whose process is gone: only
    names carrying their digest, only folders (never a link) of this user, only where the
    system tells which processes live (``/proc``)."""
    if _process_start(os.getpid()) is None or not _pid_space():
        return
    name_re = re.compile(rf"{re.escape(prefix)}(\d+)-(\d+)-([0-9a-f]{{12}})-{_SCRATCH_RANDOM}")
    try:
        entries = os.listdir(parent)
    except OSError:
        return
    for name in entries:
        m = name_re.fullmatch(name)
        if m is None:
            continue
        pid, start, digest = m.groups()
        if digest != _scratch_digest(prefix, pid, start) or _process_start(int(pid)) == start:
            continue
        path = parent / name
        try:
            st = os.lstat(path)
        except OSError:
            continue
        if stat.S_ISDIR(st.st_mode) and st.st_uid == os.getuid():
            shutil.rmtree(path, ignore_errors=True)


def make_scratch_folder(prefix: str) -> Path:
    """A new private folder (mode 0700) in the temporary folder, named ``PREFIX…`` after this
    process (see above), once the ``PREFIX…`` folders of killed processes are removed. The
    caller removes it (:func:`scratch_folder` does)."""
    parent = Path(tempfile.gettempdir())
    _drop_dead_scratch(prefix, parent)
    pid = str(os.getpid())
    start = _process_start(os.getpid()) or "0"
    return Path(tempfile.mkdtemp(prefix=f"{prefix}{pid}-{start}-"
                                        f"{_scratch_digest(prefix, pid, start)}-", dir=parent))


@contextmanager
def scratch_folder(prefix: str):
    """:func:`make_scratch_folder` for the block (its path as a string), removed at its end."""
    path = make_scratch_folder(prefix)
    try:
        yield str(path)
    finally:
        shutil.rmtree(path, ignore_errors=True)


def output_path(outputs: OutputFiles | None, target: str | os.PathLike, flag: str) -> Path:
    """Where to write the output ``target``: a temporary file of ``outputs``, or ``target``
    itself without ``outputs`` (a library call writing one file at once)."""
    return Path(target) if outputs is None else outputs.path(target, flag)


# ------------------------------------------------------------------------------ the lock

#: run folders whose lock this process holds: real path -> [fd, depth]
_held: dict[str, list[int]] = {}


def _close_locks_in_child() -> None:
    """In a process forked from one holding run folder locks (a pool of workers): close its
    copies of the lock files. A flock belongs to the open file, which a fork shares: a worker
    that outlived its killed run (blocked on the pipe to it) held the lock, and every later
    run into that --out was refused, naming the dead run's pid."""
    for fd, _ in list(_held.values()):
        try:
            os.close(fd)
        except OSError:
            pass
    _held.clear()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_close_locks_in_child)


def _key(out: Path) -> str:
    try:
        return os.path.join(os.path.realpath(out.parent), out.name)
    except FileNotFoundError:  # relative to a removed current folder: check_run_folder says so
        return os.fspath(out)


def _siblings(out: Path, kind: str) -> list[Path]:
    """Entries named ``.NAME.KIND-*`` beside ``out`` (whoever made them)."""
    prefix = f".{out.name}.{kind}-"
    try:
        return sorted(p for p in out.parent.iterdir() if p.name.startswith(prefix))
    except OSError:
        return []


def _recover(out: Path) -> None:
    """Under the lock: restore a run lost between the two renames, drop dead leftovers.

    Only entries this program made are touched (:func:`pipeline.outputs.own_folder`, the lock
    file's proof); a user's entry of the same name is left as it is.
    """
    olds = [p for p in _siblings(out, "old") if own_folder(p)]
    if olds and not os.path.lexists(out):
        newest = max(olds, key=lambda p: p.lstat().st_ctime)
        _rename_noreplace(newest, out)
        olds.remove(newest)
        print(f"note: restored the previous run {out} from {newest.name} (a run was stopped "
              "while putting its folder in place)", file=sys.stderr)
    for p in olds + [p for p in _siblings(out, "tmp") if own_folder(p)]:
        _remove_own(p)
    for p in _siblings(out, "lock"):
        _drop_dead_lock(p)


def _remove_own(folder: Path) -> None:
    """Remove ``folder``, a run or staging folder of ours, so that a kill halfway leaves one
    the next run still knows as its own and removes: it is first marked as a staging folder
    (a run folder missing some of its files is no longer one), and its marker goes last."""
    try:
        write_run_marker(folder, finished=False)
        entries = list(os.scandir(folder))
    except OSError:
        shutil.rmtree(folder, ignore_errors=True)
        return
    for entry in entries:
        if entry.name == RUN_MARKER:
            continue
        try:
            if entry.is_dir(follow_symlinks=False):
                shutil.rmtree(entry.path, ignore_errors=True)
            else:
                os.unlink(entry.path)
        except OSError:
            pass
    shutil.rmtree(folder, ignore_errors=True)


@contextmanager
def claim_run_folder(out: str | os.PathLike, inputs=(), flag: str = "--out"):
    """Check ``out`` (:func:`pipeline.outputs.check_run_folder`) and hold its lock.

    Commands enter it before doing any work, so a bad or busy ``--out`` is refused at once;
    :func:`atomic_run_folder` inside it reuses the lock. Re-entrant within one process.

    Raises
    ------
    InputError
        ``out`` may not be replaced (see :mod:`pipeline.outputs`), another live run holds
        it (the message names its pid), or ``.NAME.lock`` beside it is not a lock of ours.
    """
    out = Path(out)
    key = _key(out)
    if key in _held:
        _held[key][1] += 1
        try:
            yield out
        finally:
            _held[key][1] -= 1
        return
    check_run_folder(out, inputs, flag)
    made = _missing_parents(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    try:
        lock = out.parent / f".{out.name}.lock"
        fd = _lock(lock, out, flag)
        try:
            _held[key] = [fd, 1]
            try:
                _recover(out)
                check_run_folder(out, inputs, flag)  # the restored folder, if any, too
                yield out
            finally:
                del _held[key]
                _unlink_if_same(lock, fd)  # while still locked: see _lock; only our own file
        finally:
            os.close(fd)  # releases the flock
    finally:
        if not out.exists():
            _remove_empty(made)


@contextmanager
def reading_run_folder(folder: str | os.PathLike, flag: str = "RUN_DIR"):
    """Hold the lock of the run folder ``folder`` while a reader reads it (and writes into
    it: ``viz.saved_run``'s recording), so that no run replaces it meanwhile and the files
    read are one run's. Unlike :func:`claim_run_folder` the folder is not checked: a reader
    may read a run folder holding files of a user's.

    Where no lock can be made beside it (a read-only parent folder), no run can take it
    either: the block runs without one.

    Raises
    ------
    InputError
        A live run holds the folder (the message names its pid), or ``.NAME.lock`` beside
        it is not a lock of ours.
    """
    folder = Path(os.path.realpath(folder))
    key = _key(folder)
    if key in _held:
        yield folder
        return
    lock = folder.parent / f".{folder.name}.lock"
    try:
        fd = _lock(lock, folder, flag, busy="wait for it to finish, then read it")
    except OSError:  # no lock can be made here, so no run can be writing the folder
        yield folder
        return
    try:
        _held[key] = [fd, 1]
        try:
            yield folder
        finally:
            del _held[key]
            _unlink_if_same(lock, fd)
    finally:
        os.close(fd)


@contextmanager
def staging_beside(out: str | os.PathLike):
    """Yield a new staging folder ``.NAME.tmp-R`` beside the run folder ``out`` (whose lock
    the caller holds), to write a file in and then rename it into ``out``: a command killed
    meanwhile leaves it where the next run into ``out`` removes it, whereas a temporary file
    left inside ``out`` is a file the run did not write, and keeps every later run from
    replacing the folder. Removed at the end; ``None`` where none can be made there (a
    read-only parent folder)."""
    out = Path(out)
    try:
        tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.tmp-", dir=out.parent))
    except OSError:
        yield None
        return
    try:
        write_run_marker(tmp, finished=False)
        same_disk = os.stat(tmp).st_dev == os.stat(out).st_dev  # else no rename: a mount point
        yield tmp if same_disk else None
    finally:
        _remove_own(tmp)


def _missing_parents(out: Path) -> list[Path]:
    """The folders above ``out`` that do not exist yet, deepest first (``runs/`` of a default
    ``--out``): made for the run, removed again when it writes no folder."""
    missing = []
    for parent in out.absolute().parents:
        if parent.exists() or parent.is_symlink():
            break
        missing.append(parent)
    return missing


def _remove_empty(folders: list[Path]) -> None:
    """Remove each of ``folders`` (deepest first) while it is empty: a run refused on its
    input leaves no empty ``runs/`` behind; a folder another run wrote into stays."""
    for folder in folders:
        try:
            folder.rmdir()
        except OSError:
            return


_LOCK_HEAD = "formation-match lock"

#: what a command refused a run folder that a live run holds is told to do
_BUSY_WRITER = "wait for it to finish or choose another --out"


def _lock_pid(fd: int) -> str | None:
    """The pid written in the open lock file ``fd``; None when it is not a lock this program
    wrote (not a regular file, or its first line lacks the proof of its own inode)."""
    st = os.fstat(fd)
    if not stat.S_ISREG(st.st_mode):
        return None
    lines = os.pread(fd, 256, 0).decode("utf-8", errors="replace").splitlines()
    if len(lines) < 2 or lines[0] != f"{_LOCK_HEAD} {ownership_proof(st, 'lock')}" \
            or not lines[1].startswith("pid "):
        return None
    return lines[1][4:].strip() or "?"


def _new_lock(lock: Path) -> tuple[int, Path]:
    """A locked lock file of ours under a random name ``.NAME.lock-R``, its content written."""
    fd, tmp = tempfile.mkstemp(prefix=f"{lock.name}-", dir=lock.parent)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # a new file: nobody else holds it
        os.write(fd, f"{_LOCK_HEAD} {ownership_proof(os.fstat(fd), 'lock')}\n"
                     f"pid {os.getpid()}\n".encode())
        os.fchmod(fd, 0o666 & ~_umask())
    except BaseException:
        os.close(fd)
        os.unlink(tmp)
        raise
    return fd, Path(tmp)


def _lock(lock: Path, out: Path, flag: str, busy: str = _BUSY_WRITER) -> int:
    """Hold ``lock``: our own lock file, locked and written first, is put at ``lock`` without
    replacing anything; an existing lock of a dead run is removed first. The fd. ``busy``
    says what to do when a live run holds it."""
    fd, tmp = _new_lock(lock)
    try:
        while True:
            try:
                publish(tmp, lock, replace=False)
                return fd
            except FileExistsError:
                _clear_stale_lock(lock, out, flag, busy)
    except BaseException:
        os.close(fd)
        if os.path.lexists(tmp):
            os.unlink(tmp)
        raise


def _open_entry(path: Path) -> int | None:
    """``path`` opened read only without following a link or blocking; None if gone."""
    try:
        return os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
    except FileNotFoundError:
        return None


def _clear_stale_lock(lock: Path, out: Path, flag: str, busy: str = _BUSY_WRITER) -> None:
    """``lock`` exists: InputError when a live run holds it or it is not ours; removed when
    its run died."""
    where = f"{flag} {str(out)!r}: {str(lock)!r} beside it"
    try:
        efd = _open_entry(lock)
    except OSError as exc:
        if exc.errno != errno.ELOOP:
            raise
        raise InputError(f"{where} is a symbolic link, not a lock file of formation-match; it "
                         "is never written through or removed: move it away yourself, or "
                         "choose another --out") from None
    if efd is None:
        return
    try:
        pid = _lock_pid(efd)
        if pid is None:
            raise InputError(f"{where} is not a lock file of formation-match (it lacks the "
                             "first line a run writes there); it is never replaced or removed: "
                             "move it away yourself, or choose another --out")
        try:
            fcntl.flock(efd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise InputError(f"{flag} {str(out)!r} is being written by another run (pid {pid}); "
                             f"{busy}") from None
        _unlink_if_same(lock, efd)  # its run died
    finally:
        os.close(efd)


def _unlink_if_same(path: Path, fd: int) -> None:
    """Remove ``path`` if it is still the file open as ``fd`` (nobody put another there)."""
    try:
        if os.lstat(path).st_ino == os.fstat(fd).st_ino:
            os.unlink(path)
    except FileNotFoundError:
        pass


def _drop_dead_lock(path: Path) -> None:
    """Remove ``.NAME.lock-R`` if it is a lock file of ours that no live process holds."""
    try:
        fd = _open_entry(path)
    except OSError:
        return
    if fd is None:
        return
    try:
        if _lock_pid(fd) is None:
            return
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            return  # a live run is taking its lock
        _unlink_if_same(path, fd)
    except OSError:
        return
    finally:
        os.close(fd)


# ------------------------------------------------------------------------------ the swap

def _exchange(a: Path, b: Path) -> bool:
    """Swap ``a`` and ``b`` in one system call; False where the system cannot."""
    return _rename2(a, b, _RENAME_EXCHANGE)


def _discard_previous(old: Path, out: Path) -> None:
    """Delete the previous run, now at ``old``, unless something of a user's came into it
    while this run worked: then it is kept under that name, and a warning says so."""
    try:
        os.rmdir(old)  # an empty folder given as --out: nothing to lose
        return
    except OSError:
        pass
    problem = run_folder_problem(old)
    if problem is None:
        _remove_own(old)
        return
    print(f"warning: the previous run in {out} was not deleted: {problem}; it is kept as "
          f"{old}", file=sys.stderr)


#: the outputs this process has put in place (files of :class:`OutputFiles`, run folders),
#: so that an interrupt after them is not reported as one that wrote nothing
_put_in_place_so_far: list[Path] = []


def outputs_in_place() -> list[Path]:
    """The outputs put in place since :func:`forget_outputs_in_place`, in order."""
    return list(_put_in_place_so_far)


def forget_outputs_in_place() -> None:
    """Start a new command's record of :func:`outputs_in_place`."""
    _put_in_place_so_far.clear()


def note_output_in_place(path: str | os.PathLike) -> None:
    """Add ``path``, an output put in place by other means than this module's (a recording
    :func:`viz.rerun_log.log_run` renamed into place), to :func:`outputs_in_place`."""
    _put_in_place_so_far.append(Path(path))


def _put_in_place(staged: Path, out: Path) -> None:
    """Replace ``out`` by ``staged`` so that one of the two complete runs is always at ``out``."""
    _put_in_place_so_far.append(out)  # before: an interrupt may end it halfway
    if not os.path.lexists(out):
        _rename_noreplace(staged, out)
        return
    if _exchange(staged, out):
        _discard_previous(staged, out)  # now holds the old run
        return
    old = out.parent / f".{out.name}.old-{secrets.token_hex(6)}"
    _rename_noreplace(out, old)
    os.rename(staged, out)  # a kill before this line is repaired by _recover
    _discard_previous(old, out)


@contextmanager
def atomic_run_folder(out: str | os.PathLike, inputs=()):
    """Yield a staging folder; on success it is put in place of ``out`` atomically.

    The staging folder gets the run marker (first saying that this program made it, at the
    end listing what the run wrote). Holds (or reuses) the lock of :func:`claim_run_folder`.
    On any error the staging folder is removed and ``out`` is left as it was.

    Example
    -------
    >>> import pathlib, tempfile
    >>> out = pathlib.Path(tempfile.mkdtemp()) / "demo"
    >>> with atomic_run_folder(out) as tmp:
    ...     _ = (tmp / "report.json").write_text("{}")
    >>> sorted(p.name for p in out.parent.iterdir())  # no temporary folder left
    ['demo']
    >>> sorted(p.name for p in out.iterdir())
    ['.formation-match-run', 'report.json']
    """
    out = Path(out)
    with ExitStack() as claim:
        claim.enter_context(claim_run_folder(out, inputs))
        tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.tmp-", dir=out.parent))
        try:
            write_run_marker(tmp, finished=False)
            yield tmp
            write_run_marker(tmp, finished=True)
            publish_mode(tmp, directory=True)
            check_run_folder(out, inputs)  # nothing foreign was put there meanwhile
            if _together:  # put in place with the others (publish_together), lock kept
                _together[-1].stage(tmp, out, inputs, claim.pop_all())
                return
            _put_in_place(tmp, out)
        except BaseException:
            _remove_own(tmp)
            raise


class _Together:
    """The run folders staged inside one :func:`publish_together`, their locks, and what
    to write once they are in place."""

    def __init__(self) -> None:
        self.staged: list[tuple[Path, Path, tuple]] = []
        self.locks = ExitStack()
        self.after: list = []

    def stage(self, tmp: Path, out: Path, inputs, claim: ExitStack) -> None:
        self.locks.enter_context(claim)  # the folder's lock, held until all are in place
        self.staged.append((tmp, out, tuple(inputs)))

    def staged_folder(self, out: str | os.PathLike) -> Path:
        """Where the run folder for ``out`` is staged until the block ends."""
        key = _key(Path(out))
        return next(tmp for tmp, o, _ in self.staged if _key(o) == key)

    def then(self, write) -> None:
        """Call ``write()`` right after the folders are in place, within the held signals
        (e.g. summary files naming them)."""
        self.after.append(write)


_together: list[_Together] = []


@contextmanager
def publish_together():
    """Run folders written inside (:func:`atomic_run_folder`) are put in place together when
    the block ends without error, each replacing its previous run; on an error or an interrupt
    inside, every staged folder is removed and no previous run is touched.

    The swaps and the writers given to ``then`` run with SIGINT, SIGTERM and SIGHUP held (in
    the main thread): a signal that arrives then is acted on once all are in place — an
    interrupt, then too late to stop anything, is reported and the command ends normally; a
    SIGTERM or a SIGHUP (a closed terminal) is raised again, and ends the process as it would
    have (or is ignored, where it was ignored: ``nohup``).

    Example
    -------
    >>> import pathlib, tempfile
    >>> parent = pathlib.Path(tempfile.mkdtemp())
    >>> with publish_together():
    ...     for name in ("a", "b"):
    ...         with atomic_run_folder(parent / name) as tmp:
    ...             _ = (tmp / "report.json").write_text(name)
    ...         assert not (parent / name).exists()  # not yet
    >>> sorted(p.name for p in parent.iterdir())
    ['a', 'b']
    """
    together = _Together()
    _together.append(together)
    try:
        with together.locks:
            yield together
            with _held_signals() as got:
                for _, out, inputs in together.staged:  # every one checked before any swap
                    check_run_folder(out, inputs)
                for tmp, out, _ in together.staged:
                    _put_in_place(tmp, out)
                together.staged.clear()
                for write in together.after:
                    write()
            if signal.SIGINT in got:
                print("interrupt received while the runs were put in place: they are complete",
                      file=sys.stderr)
            for sig in _HELD[1:]:
                if sig in got:
                    signal.raise_signal(sig)
    finally:
        _together.remove(together)
        for tmp, _, _ in together.staged:  # not put in place: an error or an interrupt
            _remove_own(tmp)


#: the signals :func:`publish_together` holds while the folders are put in place
_HELD = (signal.SIGINT, signal.SIGTERM) + ((signal.SIGHUP,) if hasattr(signal, "SIGHUP")
                                          else ())


@contextmanager
def _held_signals():
    """Hold SIGINT, SIGTERM and SIGHUP for the block (main thread only); yields the set of
    those that arrived, for the caller to act on after it."""
    got: set = set()
    if threading.current_thread() is not threading.main_thread():
        yield got
        return
    old = {}
    try:
        for sig in _HELD:
            old[sig] = signal.signal(sig, lambda signum, frame: got.add(signum))
        yield got
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)
