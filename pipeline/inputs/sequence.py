"""A folder of per-robot frame sequences (``run-images DIR --sequence``).

``DIR`` holds one sub-folder per robot (robots in the sub-folders' name order; hidden
folders skipped); each sub-folder holds that robot's frames, taken in name order. Step ``k``
is every robot's ``k``-th frame, so every robot must hold the same number of frames (at
least two: a single frame is no sequence). Intrinsics as :func:`pipeline.inputs.photos.load_folder`:
with ``"auto"`` a sub-folder's own ``K.txt`` serves its robot, a ``DIR/K.txt`` every
robot without one, otherwise EXIF or the stated guess.
"""

from __future__ import annotations

import dataclasses
import logging
import re
from dataclasses import dataclass
from decimal import Decimal
from pathlib import Path

from pipeline.errors import InputError
from pipeline.inputs.photos import (
    image_paths,
    is_utf8_name,
    left_out_images,
    load_folder,
    read_k_txt,
    warn_misnamed_k_txt,
    why_missing,
)
from pipeline.types import View

__all__ = ["PhotoSequence", "load_sequence"]

log = logging.getLogger(__name__)


@dataclass
class PhotoSequence:
    """Frames of a team in motion read from folders.

    robots : list[str] — the sub-folders' names, robot ``i`` = ``robots[i]``
    steps : int
    views : list[View] — ``views[k * n_robots + i]`` = robot ``i``'s frame of step ``k``,
        named ``<sub-folder>/<file>``
    ignored : list[str] — images directly in ``DIR`` (no robot's: not used)
    empty : list[str] — sub-folders holding no image (no robot: not used)
    broken : list[str] — symbolic links in ``DIR`` leading nowhere (a robot's folder on a
        drive not mounted: no robot, not used)
    """

    robots: list
    steps: int
    views: list
    ignored: list = dataclasses.field(default_factory=list)
    empty: list = dataclasses.field(default_factory=list)
    broken: list = dataclasses.field(default_factory=list)

    @property
    def n_robots(self) -> int:
        return len(self.robots)


def load_sequence(directory: str | Path, max_size: int | None = 1600,
                  intrinsics: str | Path = "auto", check_robots=None) -> PhotoSequence:
    """Read ``DIR`` (module docstring) into a :class:`PhotoSequence`.

    ``check_robots``: called with the robots' sub-folder names, in robot order, once the
    folder is listed and before any frame is decoded (e.g. a comm-graph file naming them);
    it raises to refuse them.

    Raises
    ------
    InputError
        ``DIR`` missing or not a folder, fewer than two robot sub-folders holding images
        (sub-folders without any are no robots: :attr:`PhotoSequence.empty`), sub-folders with
        different numbers of frames, or any error of :func:`~pipeline.inputs.photos.load_folder`.
    """
    directory = Path(directory)
    if not directory.exists():
        raise InputError(f"--sequence {str(directory)!r} {why_missing(directory)}; expected "
                         "a folder holding one sub-folder of frames per robot")
    if not directory.is_dir():
        raise InputError(f"--sequence {str(directory)!r}: expected a folder holding one "
                         "sub-folder of frames per robot")
    subs = sorted((p for p in directory.iterdir() if p.is_dir() and not p.name.startswith(".")),
                  key=lambda p: p.name)
    empty = [p.name for p in subs if not image_paths(p)]  # e.g. a run folder: no robot
    for p in subs:  # frames of a format not read, a nested robot folder: said why
        why = left_out_images(p, robot_folder=True) if p.name in empty else []
        if why:
            log.warning("warning: %s", f"{str(p)!r}: {'; '.join(why)}")
    subs = [p for p in subs if p.name not in empty]
    if len(subs) < 2:
        flat = image_paths(directory)
        raise InputError(f"--sequence {str(directory)!r}: {len(subs)} robot sub-folder(s) "
                         "holding images; a team needs at least two (one sub-folder of frames "
                         "per robot)" + (
                             f"; its {len(flat)} image(s) directly in it belong to no robot: "
                             "to run them as one snapshot of a team, drop --sequence"
                             if flat else ""))
    not_utf8 = [p.name for p in subs if not is_utf8_name(p.name)]
    if not_utf8:
        raise InputError(f"--sequence {str(directory)!r}: {len(not_utf8)} robot sub-folder "
                         f"name(s) are not UTF-8 text ({', '.join(repr(n) for n in not_utf8[:5])}"
                         "): the outputs name every frame in UTF-8 (images.csv, report.json); "
                         "rename them, e.g. with convmv -f latin1 -t utf8")
    shared = intrinsics
    if intrinsics == "auto" and (directory / "K.txt").is_file():
        shared = directory / "K.txt"
    elif intrinsics == "auto":
        warn_misnamed_k_txt(directory)
    counts = {p.name: len(image_paths(p)) for p in subs}
    if len(set(counts.values())) > 1:
        raise InputError(f"--sequence {str(directory)!r}: robots hold different numbers of "
                         f"frames ({', '.join(f'{k}: {v}' for k, v in counts.items())}); step "
                         "k is every robot's k-th frame, give every robot the same number")
    if max(counts.values()) == 1:
        raise InputError(f"--sequence {str(directory)!r}: every robot holds one frame (one "
                         "step); a sequence needs two steps or more. For one snapshot of the "
                         "team, put the frames in one folder and drop --sequence")
    pair = _number_order_breach([p.name for p in subs])
    if pair:
        log.warning("warning: %s", f"--sequence {str(directory)!r}: the robot sub-folders sort "
                    f"by name otherwise than by number ({pair[0]} before {pair[1]}): robot i "
                    "is the i-th by name, and line, ring and seq:K follow that order; "
                    f"zero-pad the numbers (e.g. {_zero_padded(pair[1])}) for number order")
    breaches = {p.name: _number_order_breach([f.name for f in image_paths(p)]) for p in subs}
    breaches = {robot: pair for robot, pair in breaches.items() if pair}
    if breaches:
        robot, pair = next(iter(breaches.items()))
        log.warning("warning: %s", f"{len(breaches)} robot(s) ({', '.join(list(breaches)[:3])}"
                    f"{', ...' if len(breaches) > 3 else ''}) hold frames that sort by name "
                    f"otherwise than by number ({robot}/{pair[0]} before {robot}/{pair[1]}): "
                    "step k is every robot's k-th frame by name; zero-pad the numbers (e.g. "
                    f"{_zero_padded(pair[1])}) for number order")
    if check_robots is not None:
        check_robots([p.name for p in subs])
    # the most specific K.txt wins: a robot's own camera is not overridden by the team's
    own = {p.name: intrinsics == "auto" and (p / "K.txt").is_file() for p in subs}
    if shared not in ("auto", "exif") and not all(own.values()):
        # read once here: an error while loading the first robot named that robot, though
        # the file serves every robot without a K.txt of its own
        try:
            read_k_txt(Path(shared))
        except InputError as exc:
            what = ("the folder's shared K.txt, serving every robot without a K.txt of its own"
                    if intrinsics == "auto" else "--intrinsics, serving every robot")
            raise InputError(f"--sequence {str(directory)!r}: {what}: {exc}") from None
    for p in subs:
        if intrinsics == "auto" and not own[p.name] and shared != "auto":
            # load_folder reads the team's K.txt and does not look in the robot's folder
            warn_misnamed_k_txt(p, f"{str(shared)!r} serves robot {p.name!r} instead")
    per_robot = [_load_robot(p, max_size, "auto" if own[p.name] else shared) for p in subs]
    steps = len(per_robot[0])
    views: list[View] = []
    for k in range(steps):
        for p, vs in zip(subs, per_robot, strict=True):
            views.append(dataclasses.replace(vs[k], name=f"{p.name}/{vs[k].name}"))
    broken = sorted(p.name for p in directory.iterdir()
                    if p.is_symlink() and not p.exists() and not p.name.startswith("."))
    return PhotoSequence(robots=[p.name for p in subs], steps=steps, views=views,
                         ignored=[p.name for p in image_paths(directory)], empty=empty,
                         broken=broken)


def _load_robot(folder: Path, max_size: int | None, intrinsics) -> list[View]:
    """:func:`load_folder` of one robot's sub-folder; an error that names a file of it by
    its name alone (robots' frames often share names) names the sub-folder too."""
    try:
        return load_folder(folder, max_size=max_size, intrinsics=intrinsics)
    except InputError as exc:
        message = str(exc)
        if str(folder) in message:
            raise
        raise InputError(f"robot {folder.name!r} ({str(folder)!r}): {message}") from None


#: a number in a file name: digits, with their decimals where one point joins two runs of
#: digits (a timestamp such as ``1700000000.15``); digits joined by more points (a date
#: ``2024.2.01``) are numbers each
_NUMBER = re.compile(r"(?<!\d)(?<!\d\.)(\d+)(\.\d+)(?!\.?\d)|(\d+)()")


def _number_order_breach(names: list[str]) -> tuple[str, str] | None:
    """The first two of ``names`` (in name order) that number order puts the other way
    round (``frame10.png`` before ``frame2.png``), or None when both orders agree. Digits
    after a number's decimal point are its fraction: ``1700000000.15.png`` comes before
    ``1700000000.2.png`` in both orders (timestamps written without trailing zeros)."""
    def key(name):
        out, at = [], 0
        for m in _NUMBER.finditer(name):
            if m.start() > at:
                out.append((1, 0, name[at:m.start()]))
            out.append((0, Decimal(m.group()), ""))
            at = m.end()
        if at < len(name):
            out.append((1, 0, name[at:]))
        return out

    by_number = sorted(names, key=key)
    for a, b in zip(names, by_number, strict=True):
        if a != b:
            return a, b
    return None


def _zero_padded(name: str) -> str:
    """``name`` with its numbers written with three digits or more before their decimal
    point (``frame002.png``; ``t002.5.png``)."""
    return _NUMBER.sub(lambda m: (m.group(1) or m.group(3)).zfill(3) + (m.group(2) or ""), name)
