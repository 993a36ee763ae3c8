"""Where a command may write: the one guard every output path goes through.

Rules (each broken rule is an :class:`~pipeline.errors.InputError` naming the path, the flag
and what to do, raised before any work is done):

- An output never resolves (after following symbolic links, or as a hard link) to an input
  of the same command, nor to another output of it.
- An output file is a regular file or a new name: a folder, a device (``/dev/null``), a FIFO,
  a socket or a symbolic link is never replaced or written through.
- An existing output file is replaced only with ``--overwrite``.
- A run folder (``--out`` of ``run-formation`` / ``run-images``) is replaced as a whole, so it
  must be a new name, an empty folder or a folder whose run marker (:data:`RUN_MARKER`,
  written into every run folder) proves that a run wrote it and that every entry in it is one
  that run wrote, unchanged (see :func:`run_folder_problem`); it may not be a symbolic link,
  ``/``, the current folder or one of its parents, nor an input or a folder holding an input.
- The folder an output goes into must be writable.

Reading: :func:`require_input_file` says "is a folder" or "no such file" for a bad input file.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import stat
import tempfile
from collections.abc import Iterable
from pathlib import Path

from pipeline.errors import InputError

__all__ = ["RUN_MARKER", "check_output_files", "check_run_folder", "ownership_proof",
           "read_small_text", "refuse_unsafe_target", "require_input_file", "run_folder_problem",
           "own_folder", "write_run_marker"]

#: File written into every run folder; only a folder holding it may be replaced by a new run.
RUN_MARKER = ".formation-match-run"
#: first line of :data:`RUN_MARKER` in a finished run / in a staging folder being written
_RUN_HEAD, _STAGING_HEAD = "formation-match run folder", "formation-match staging folder"
#: largest marker read (its listing grows with the files of the run: a few hundred bytes each)
_MARKER_MAX_BYTES = 4 * 2**20


def ownership_proof(st: os.stat_result, kind: str) -> str:
    """A digest tying an entry this program created to its inode (``kind``: what it is, e.g.
    ``"folder"``, ``"lock"``). Written into the entry when it is made, it tells the entry apart
    from anything a user put under a similar name: a copy, a rename of another file or a
    hand-written one does not carry the digest of its own inode."""
    h = hashlib.blake2b(f"{kind} {st.st_ino}".encode(), digest_size=16,
                        key=b"formation-match: entry created by this program")
    return h.hexdigest()


def _listing(folder: Path) -> list[list]:
    """``[relative path, kind, size, mtime_ns]`` of every entry below ``folder`` but the
    marker, sorted; symbolic links are listed, never followed (kind ``l``; ``d`` folder,
    ``f`` file, ``o`` other)."""
    out = []

    def walk(d: Path, rel: str) -> None:
        with os.scandir(d) as it:
            entries = sorted(it, key=lambda e: e.name)
        for e in entries:
            name = f"{rel}{e.name}"
            if name == RUN_MARKER:
                continue
            st = e.stat(follow_symlinks=False)
            if stat.S_ISDIR(st.st_mode):
                out.append([name, "d", 0, 0])
                walk(Path(e.path), name + "/")
            elif stat.S_ISREG(st.st_mode):
                out.append([name, "f", st.st_size, st.st_mtime_ns])
            else:
                out.append([name, "l" if stat.S_ISLNK(st.st_mode) else "o", 0, 0])

    walk(folder, "")
    return out


def _files_digest(listing: list[list]) -> str:
    body = json.dumps(listing, separators=(",", ":")).encode()
    return hashlib.blake2b(body, digest_size=16,
                           key=b"formation-match: files of a finished run").hexdigest()


def write_run_marker(folder: str | os.PathLike, finished: bool) -> None:
    """Write :data:`RUN_MARKER` into ``folder``, a folder this program just created.

    Both states carry :func:`ownership_proof` of the folder's inode. A ``finished`` run's
    marker also lists every entry of the folder (path, size, modification time) with a digest
    of that list, so that a later run replaces it only while it holds nothing else
    (:func:`run_folder_problem`); a staging folder's marker (``finished=False``) only says that
    this program made it, so that a run killed while writing it leaves a folder the next run
    may remove.
    """
    folder = Path(folder)
    lines = [_RUN_HEAD if finished else _STAGING_HEAD,
             f"own {ownership_proof(os.lstat(folder), 'folder')}"]
    if finished:
        listing = _listing(folder)
        lines += [f"files {_files_digest(listing)}", json.dumps(listing)]
    tmp = folder / f"{RUN_MARKER}.new"
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_NOFOLLOW, 0o666)
    with os.fdopen(fd, "w", encoding="utf-8") as f:
        f.write("\n".join(lines) + "\n")
    os.replace(tmp, folder / RUN_MARKER)


def read_small_text(path: str | os.PathLike, max_bytes: int) -> str | None:
    """The UTF-8 text of the regular file ``path``; None when it is missing, not a regular
    file (a symbolic link is never followed, a FIFO never waited on), larger than
    ``max_bytes`` or not text. For files this program wrote and checks (markers,
    summaries)."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
    except OSError:
        return None
    with os.fdopen(fd, "rb") as f:
        if not stat.S_ISREG(os.fstat(f.fileno()).st_mode):
            return None
        data = f.read(max_bytes + 1)
    try:
        return data.decode("utf-8") if len(data) <= max_bytes else None
    except UnicodeDecodeError:
        return None


def _read_marker(folder: Path) -> list[str] | None:
    """The marker's lines, or None (see :func:`read_small_text`)."""
    text = read_small_text(folder / RUN_MARKER, _MARKER_MAX_BYTES)
    return None if text is None else text.splitlines()


def _examples(names: list[str], k: int = 3) -> str:
    shown = ", ".join(repr(n) for n in names[:k])
    return shown + (f" and {len(names) - k} more" if len(names) > k else "")


def run_folder_problem(folder: str | os.PathLike, own: bool = False) -> str | None:
    """Why the existing folder ``folder`` may not be replaced (deleted) as a run, or None.

    It may be when its :data:`RUN_MARKER` is a finished run's, the marker's digest matches the
    list it holds, and every entry now in the folder is in that list with the same size and
    modification time (a file a user added or changed would be lost). With ``own``, the
    marker must also prove that this program created the folder itself (its inode), which a
    copy does not. The reason, when there is one, names what would be lost.
    """
    folder = Path(folder)
    try:
        listing = _listing(folder)
    except OSError as exc:
        return f"cannot list it ({exc.strerror})"
    lines = _read_marker(folder)
    marker = os.path.lexists(folder / RUN_MARKER)
    names = [e[0] for e in listing if "/" not in e[0]]
    holds = (f"it holds {len(names)} entr{'y' if len(names) == 1 else 'ies'} "
             f"({_examples(names)}) that replacing it would delete")
    if not marker:
        return f"it is not a formation-match run folder (no {RUN_MARKER} file in it); {holds}"
    valid = (lines is not None and len(lines) == 4 and lines[0] == _RUN_HEAD
             and lines[2] == f"files {_files_digest(_parse(lines[3]))}")
    if valid and own:
        valid = lines[1] == f"own {ownership_proof(os.lstat(folder), 'folder')}"
    if not valid:
        return (f"its {RUN_MARKER} was not written by a finished formation-match run (its "
                f"content does not check out); {holds}")
    recorded = {e[0]: e for e in _parse(lines[3])}
    foreign = [e[0] for e in listing if recorded.get(e[0]) != e]
    if foreign:
        return (f"{len(foreign)} entr{'y' if len(foreign) == 1 else 'ies'} in it "
                f"({_examples(foreign)}) {'was' if len(foreign) == 1 else 'were'} added or "
                "changed after the run wrote it; replacing the folder would delete "
                f"{'it' if len(foreign) == 1 else 'them'}")
    return None


def _parse(text: str) -> list[list]:
    try:
        data = json.loads(text)
    except ValueError:
        return []
    return data if isinstance(data, list) else []


def own_folder(folder: str | os.PathLike) -> bool:
    """True when ``folder`` (not a symbolic link) is a staging folder this program created and
    left (a run killed while writing it), holding nothing a user added later; or a finished
    run folder this program created, with nothing of a user's in it (see
    :func:`run_folder_problem`)."""
    folder = Path(folder)
    try:
        st = os.lstat(folder)
    except OSError:
        return False
    if not stat.S_ISDIR(st.st_mode):
        return False
    lines = _read_marker(folder)
    if not lines or len(lines) < 2 or lines[1] != f"own {ownership_proof(st, 'folder')}":
        return False
    if lines[0] == _STAGING_HEAD and len(lines) == 2:
        return True
    return run_folder_problem(folder, own=True) is None

Named = Iterable[tuple[str, "str | os.PathLike | None"]]


def _real(path) -> Path:
    return Path(os.path.realpath(os.fspath(path)))


def _same(a, b) -> bool:
    """``a`` and ``b`` are the same file system entry (symlinks followed, hard links too)."""
    if _real(a) == _real(b):
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def current_folder(path, flag: str) -> Path | None:
    """The current folder (its real path), or None where it was removed (the command was
    started in a folder deleted since) and ``path`` is absolute.

    Raises
    ------
    InputError
        ``path`` is relative to a current folder that was removed (naming ``flag``).
    """
    try:
        return _real(Path.cwd())
    except FileNotFoundError:
        if not os.path.isabs(path):
            raise InputError(f"{flag} {os.fspath(path)!r} is relative to the current folder, "
                             "which was removed; cd to a folder that exists, or give an "
                             f"absolute {flag}") from None
        return None


def require_input_file(path, what: str) -> Path:
    """``Path(path)`` if it names a readable regular file; else an InputError.

    Parameters
    ----------
    path : the file a flag named
    what : how to call it in the message, e.g. ``"--links"`` or ``"links file"``
    """
    p = Path(path)
    if p.is_dir():
        raise InputError(f"{what} {str(p)!r} is a folder, not a file; give the file itself")
    if not p.exists():
        raise InputError(f"{what} {str(p)!r}: no such file")
    if not p.is_file():
        raise InputError(f"{what} {str(p)!r} is not a regular file (a device, FIFO or socket); "
                         "give a file")
    return p


def _check_writable_folder(path: Path, flag: str) -> None:
    """The nearest existing ancestor of ``path`` must be a folder we may write in."""
    parent = Path(os.path.abspath(path)).parent
    while not parent.exists():
        if parent.is_symlink():  # mkdir would say only "File exists"
            raise InputError(f"{flag} {str(path)!r}: {str(parent)!r} is a symbolic link that "
                             f"leads nowhere (to {os.readlink(parent)!r}); create or mount its "
                             "target, or choose another place")
        parent = parent.parent
    if not parent.is_dir():
        raise InputError(f"{flag} {str(path)!r}: {str(parent)!r} is a file, not a folder; "
                         "choose another place")
    # a real probe, not os.access: for root every folder passes os.access, yet /proc, /sys
    # and read-only mounts refuse new files
    try:
        with tempfile.TemporaryFile(dir=parent, prefix=".fm-probe-"):
            pass
    except OSError as exc:
        raise InputError(f"{flag} {str(path)!r}: cannot write in {str(parent)!r} (read-only or "
                         f"no permission: {exc.strerror or exc}); choose a folder you can "
                         "write in") from None


def refuse_unsafe_target(path, flag: str = "output") -> None:
    """InputError if ``path`` is a symbolic link or an existing non-regular file.

    Writes replace their target by a rename; a rename over ``/dev/null``, a FIFO or a symbolic
    link would replace that special entry, so it is refused.
    """
    p = Path(path)
    if p.is_symlink():
        raise InputError(f"{flag} {str(p)!r} is a symbolic link (to {os.path.realpath(p)!r}); "
                         "outputs never replace or write through a link: give a plain file name")
    try:
        mode = p.lstat().st_mode
    except (FileNotFoundError, NotADirectoryError):  # nothing there (a file on the way: the
        return                                       # writable-folder check names it)
    if stat.S_ISDIR(mode):
        raise InputError(f"{flag} {str(p)!r} is a folder; give the name of a file to write, "
                         f"e.g. {str(p / 'out')!r}")
    if not stat.S_ISREG(mode):
        raise InputError(f"{flag} {str(p)!r} is not a regular file (a device, FIFO or socket); "
                         "it is never replaced: give the name of a file to write")


def check_output_files(outputs: Named, inputs: Named = (), overwrite: bool = False) -> None:
    """Check the output files of one command (see the module rules).

    Parameters
    ----------
    outputs : ``(flag, path)`` pairs, e.g. ``[("--out", "o.csv"), ("--report", None)]``;
        ``None`` paths are skipped
    inputs : ``(flag, path)`` pairs of the files (or folders) the command reads
    overwrite : replace existing regular files (the ``--overwrite`` flag)

    Raises
    ------
    InputError
        The first broken rule, naming the flag and the path.
    """
    for flag, p in outputs:
        if p is not None and not os.fspath(p):  # Path("") would read as "."
            raise InputError(f"{flag} '' is empty: give the name of a file to write")
    for flag, p in inputs:
        if p is not None and not os.fspath(p):
            raise InputError(f"{flag} '' is empty: give the file to read")
    for flag, p in outputs:  # Path('new/') reads as the file 'new'
        if p is not None and os.fspath(p) == "-":
            raise InputError(f"{flag} '-': outputs are written to files, never to stdout; give "
                             "a file name ('./-' for a file named '-')")
        if p is not None and os.fspath(p).endswith(os.sep):
            raise InputError(f"{flag} {os.fspath(p)!r} ends with {os.sep!r}, so it names a "
                             "folder; give the name of a file to write, e.g. "
                             f"{os.path.join(os.fspath(p), 'out')!r}")
    outs = [(f, Path(p)) for f, p in outputs if p is not None]
    ins = [(f, Path(p)) for f, p in inputs if p is not None]
    for flag, p in outs:
        current_folder(p, flag)
    for flag, p in outs:
        if not str(p) or p.name in ("", ".", ".."):
            raise InputError(f"{flag} {str(p)!r}: give the name of a file to write")
        refuse_unsafe_target(p, flag)
        for in_flag, q in ins:
            if q.exists() and _same(p, q):
                raise InputError(f"{flag} {str(p)!r} is the input file given as {in_flag} "
                                 f"({str(q)!r}); inputs are never modified: choose another "
                                 "output name")
        if p.exists() and not overwrite:
            raise InputError(f"{flag} {str(p)!r} already exists; pass --overwrite to replace it, "
                             "or choose a new name")
        _check_writable_folder(p, flag)
    for k, (flag, p) in enumerate(outs):
        for flag2, q in outs[k + 1:]:
            if _real(p) == _real(q):
                raise InputError(f"{flag} and {flag2} name the same file {str(p)!r}; give each "
                                 "output its own name")


def results_folder_problem(out, flag: str = "--out") -> str | None:
    """Why ``out`` cannot be the folder a benchmark writes its results in (``results.json``
    and the like, each file replaced at once), or None: empty, a file or a path through one, or in a
    folder that may not be written. Checked before the benchmark's work, which takes minutes."""
    if not os.fspath(out):
        return f"{flag} '' is empty: give a folder name"
    p = Path(out)
    if p.exists() and not p.is_dir():
        return (f"{flag} {str(p)!r} is a file; the results are written in a folder: give a "
                "folder name")
    try:
        _check_writable_folder(p / "results.json", flag)
    except InputError as exc:
        return str(exc).replace(repr(str(p / "results.json")), repr(str(p)), 1)
    return None


def _missing_before_dotdot(p: Path) -> Path | None:
    """The first entry of ``p`` that is no folder (missing, or a file) while a later ``..`` of
    ``p`` steps out of it (``RUN/sub/..``: the system resolves no such path, and making the
    folders above the run folder would make ``RUN/sub``), or None."""
    parts = p.parts
    if ".." not in parts[1:]:
        return None
    last = len(parts) - 1 - parts[::-1].index("..")
    for i in range(last):
        prefix = Path(*parts[:i + 1])
        if parts[i] != ".." and not prefix.is_dir():
            return prefix
    return None


#: bytes the names a run keeps beside its folder NAME add to it: ``.NAME.old-`` and 12 hex
#: digits (the longest; ``.NAME.lock-`` and ``.NAME.tmp-`` take 8 random characters,
#: :mod:`pipeline.runfolder`)
RUN_NAME_SPARE = len("..old-") + 12


def _name_too_long(p: Path) -> str | None:
    """Why the run folder ``p``'s own name leaves no room for the names a run keeps beside
    it (the file system's limit, usually 255 bytes, less :data:`RUN_NAME_SPARE`), or None."""
    parent = Path(os.path.abspath(p)).parent
    while not parent.is_dir() and parent != parent.parent:
        parent = parent.parent
    try:
        limit = os.pathconf(parent, "PC_NAME_MAX")
    except (OSError, ValueError):
        limit = 255
    n = len(os.fsencode(p.name))
    if n + RUN_NAME_SPARE <= limit:
        return None
    return (f"its name is {n} bytes long, and a run keeps '.NAME.lock-…', '.NAME.tmp-…' and "
            f"'.NAME.old-…' beside its folder: a run folder's name may be at most "
            f"{limit - RUN_NAME_SPARE} bytes here")


def _mount_point(real: Path) -> bool:
    """Whether the folder ``real`` (a real path) is a mount point, a bind mount of a folder of
    the same file system included (``/proc/self/mountinfo`` lists those; ``os.path.ismount``
    alone does not see them)."""
    if os.path.ismount(real):
        return True
    try:
        with open("/proc/self/mountinfo", "rb") as f:
            table = f.read()
    except OSError:
        return False
    want = os.fsencode(real)
    for line in table.splitlines():
        fields = line.split(b" ")
        if len(fields) > 4 and re.sub(rb"\\([0-7]{3})", lambda m: bytes([int(m[1], 8)]),
                                      fields[4]) == want:
            return True
    return False


def check_run_folder(out, inputs: Named = (), flag: str = "--out") -> Path:
    """Check that the run folder ``out`` may be (re)placed by a new run; return it as a Path.

    Raises
    ------
    InputError
        ``out`` is a symbolic link, a file, ``/``, the current folder or one of its parents,
        inside another run folder, an input or a folder holding an input, or an existing non-empty folder without the
        :data:`RUN_MARKER` of a previous run.
    """
    p = Path(out)
    if not str(out) or p.is_symlink():
        what = "is a symbolic link" if str(out) else "is empty"
        raise InputError(f"{flag} {str(out)!r} {what}; give the name of a run folder")
    cwd = current_folder(p, flag)
    gone = _missing_before_dotdot(p)
    if gone is not None:
        raise InputError(f"{flag} {str(out)!r}: {str(gone)!r} is no folder, so the '..' "
                         "after it names none (a run would make the missing folders and leave "
                         f"them behind); give the path without '..', e.g. "
                         f"{os.path.normpath(out)!r}")
    too_long = _name_too_long(p)
    if too_long is not None:
        raise InputError(f"{flag} {str(out)!r}: {too_long}; choose a shorter name")
    real = _real(p)
    if real == Path(real.anchor) or (cwd is not None and (real == cwd or real in cwd.parents)):
        raise InputError(f"{flag} {str(out)!r} is {'/' if real == Path(real.anchor) else 'the current folder or one of its parents'}; "
                         "a run folder is replaced as a whole: give a new folder name, e.g. "
                         "runs/NAME")
    for anc in real.parents:  # a run folder holds only what its run wrote
        if os.path.lexists(anc / RUN_MARKER):
            raise InputError(f"{flag} {str(out)!r} is inside the run folder {str(anc)!r}: a "
                             "run folder holds only what its run wrote (a run put in it would "
                             "block, or be deleted by, the next run there): choose an --out "
                             "outside it")
    for in_flag, q in inputs:
        if q is None:
            continue
        rq = _real(q)
        if rq == real or real in rq.parents:
            raise InputError(f"{flag} {str(out)!r} holds the input {in_flag} {str(q)!r}; a run "
                             "folder is replaced as a whole, which would delete it: choose "
                             "another --out")
    if p.exists():
        if not p.is_dir():
            raise InputError(f"{flag} {str(out)!r} is a file; a run is written as a folder: "
                             "choose a folder name")
        if _mount_point(real):  # renaming it fails (EBUSY), after the whole run
            raise InputError(f"{flag} {str(out)!r} is a mount point; a run folder is put in "
                             "place by renaming it, which a mount point cannot be: give a "
                             f"folder inside it, e.g. {str(p / 'run')!r}")
        try:
            empty = next(p.iterdir(), None) is None
        except OSError as exc:
            raise InputError(f"{flag} {str(out)!r}: cannot list it ({exc.strerror})") from None
        problem = None if empty else run_folder_problem(p)
        if problem is not None:
            raise InputError(f"{flag} {str(out)!r} exists and may not be replaced: {problem}; "
                             "choose another --out, or move what you keep away yourself")
    _check_writable_folder(p, flag)
    return p
