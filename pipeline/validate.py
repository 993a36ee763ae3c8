"""Checks of numbers a user gives on the command line or in a file, before any work is done.

Each check returns the value (converted) or raises :class:`~pipeline.errors.InputError`
naming the flag, the value and the accepted range. The stated limits:

- ``--tol-px``: a finite number of pixels > 0.
- a limit (``--max-memory-gb``, ``--team-timeout``, ``--round-timeout``): a finite number above
  0 and at most the option's own bound (:func:`positive_number`).
- ``--threads``: ``-1`` (all cores) or ``1 .. MAX_THREADS``.
- a seed (``--fault-seed``, ``--seed``): an integer in ``0 .. 2**63 - 1`` (numpy's seeding
  takes non-negative integers).
- ``--max-features``: a count of features per image in ``MIN_FEATURES .. MAX_FEATURES``
  (:mod:`pipeline.matching.methods`).
- ``--size WxH`` of a rendered formation: each side ``64x48`` at least and at most
  :data:`MAX_RENDER_SIDE`, at most :data:`MAX_RENDER_PIXELS` pixels (the renderer holds
  several full-size float arrays per camera: ~100 bytes a pixel over all of them).
- ``--robots`` of a parametric formation: ``2 .. MAX_ROBOTS`` (robots drive 0.8 m apart, line
  abreast: beyond a few hundred most see nothing of the facade; the memory of a run is
  counted by :mod:`pipeline.budget` on top).
- a focal length in pixels: finite and within ``FOCAL_RANGE`` times the image's longest
  side (outside it the field of view is either wider than a fisheye's or under 0.06°; such
  a K is a typo or a corrupt file).
"""

from __future__ import annotations

import math
import numbers

from pipeline.errors import InputError

__all__ = ["not_empty", "shown", "MAX_THREADS", "MAX_RENDER_SIDE", "MAX_RENDER_PIXELS", "MAX_ROBOTS", "FOCAL_RANGE",
           "tolerance_px", "lowe_ratio", "threads", "seed", "render_size", "robots",
           "focal_px_ok", "check_focal", "is_utf8_name"]

MAX_THREADS = 1024
MAX_RENDER_SIDE = 8192
MAX_RENDER_PIXELS = 4096 * 4096
MAX_ROBOTS = 1000
#: focal length / longest image side must lie in this range
FOCAL_RANGE = (0.05, 1000.0)


def shown(value: float) -> str:
    """A number as an error message names it: short (``{:g}``) where that reads back as the
    value, else every digit it has (``{:g}`` rounds 1000001 to ``1e+06`` and 120.0000001 to
    ``120``, and a message refusing them named the limit itself as the value given).

    >>> shown(1e9), shown(-1.0), shown(1000001.0), shown(120.0000001)
    ('1e+09', '-1', '1000001.0', '120.0000001')
    """
    short = f"{value:g}"
    v = float(value)
    return short if float(short) == v or not math.isfinite(v) else repr(v)


def not_empty(value, flag: str, advice: str = "give a folder name") -> None:
    """InputError when a path option was given as ``''`` (an unset shell variable): ``Path('')``
    is the current folder, where a command would write or read something else than meant.

    >>> not_empty("runs/x", "--out")
    >>> not_empty("", "--out")
    Traceback (most recent call last):
    ...
    pipeline.errors.InputError: --out '' is empty (an unset variable?); give a folder name
    """
    if value is not None and str(value) == "":
        raise InputError(f"{flag} '' is empty (an unset variable?); {advice}")


def positive_number(value, flag: str, unit: str, top: float, what: str, example: str) -> float:
    """A finite number of ``unit`` above 0 and at most ``top`` (``nan`` would turn every
    comparison false, ``inf`` make a wait never end); the one-line error says ``what`` to give
    and ``example``.

    >>> positive_number("45", "--round-timeout", "seconds", 3600, "seconds of silence", "120")
    45.0
    >>> positive_number("nan", "--max-memory-gb", "GB", 1e6, "the memory limit in GB", "4")
    Traceback (most recent call last):
    ...
    pipeline.errors.InputError: --max-memory-gb 'nan': must be a finite number of GB above 0 (at most 1e+06), e.g. --max-memory-gb 4
    """
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{flag} {value!r}: not a number; give {what}, e.g. {flag} "
                         f"{example}") from None
    if not (math.isfinite(v) and 0 < v <= top):
        raise InputError(f"{flag} {value!r}: must be a finite number of {unit} above 0 "
                         f"(at most {top:g}), e.g. {flag} {example}")
    return v


def tolerance_px(value, flag: str = "--tol-px") -> float:
    """A positive finite tolerance in pixels."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{flag} {value!r}: not a number; give a tolerance in pixels, e.g. 2") \
            from None
    if not math.isfinite(v) or v <= 0:
        raise InputError(f"{flag} {value!r}: must be a finite number of pixels > 0, e.g. 2")
    return v


def lowe_ratio(value, flag: str = "--ratio") -> float:
    """A Lowe ratio in ``(0, 1]``."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{flag} {value!r}: not a number; give a ratio in (0, 1], e.g. 0.8") \
            from None
    if not 0.0 < v <= 1.0:  # also refuses nan
        raise InputError(f"{flag} {value!r}: must be a ratio in (0, 1], e.g. 0.8")
    return v


def threads(value, flag: str = "--threads") -> int:
    """``-1`` (all cores) or ``1 .. MAX_THREADS``."""
    v = int(value)
    if v != -1 and not 1 <= v <= MAX_THREADS:
        raise InputError(f"{flag} {value}: give -1 (all cores) or a count from 1 to "
                         f"{MAX_THREADS}")
    return v


def is_number(v) -> bool:
    """``v`` is a real number, Python's or NumPy's: not a bool, not text (which the checks of
    the Python API refuse by name rather than let ``float()`` or NumPy fail on).

    >>> is_number(2.5), is_number(3), is_number(True), is_number("2")
    (True, True, False, False)
    """
    return isinstance(v, numbers.Real) and not isinstance(v, bool)


def is_utf8_name(name: str) -> bool:
    r"""Whether a file name decoded from the file system is UTF-8 text (bytes that are not
    become lone surrogates, which no UTF-8 output can hold).

    >>> is_utf8_name("caf\u00e9.jpg"), is_utf8_name(b"caf\xe9.jpg".decode("utf-8", "surrogateescape"))
    (True, False)
    """
    try:
        name.encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True


def check_utf8_names(names, directory, why: str, rename: str = "them") -> None:
    """InputError naming the file names among ``names`` (images of ``directory``) that are not
    UTF-8 text (:func:`is_utf8_name`): ``why`` the outputs that must name them, ``rename``
    what to rename."""
    bad = [n for n in names if not is_utf8_name(n)]
    if bad:
        raise InputError(
            f"{len(bad)} image file name(s) in {str(directory)!r} are not UTF-8 text "
            f"({', '.join(repr(n) for n in bad[:5])}{', ...' if len(bad) > 5 else ''}): "
            f"{why}; rename {rename}, e.g. with convmv -f latin1 -t utf8")


def seed(value, flag: str) -> int:
    """A non-negative integer seed below ``2**63``."""
    try:
        v = int(str(value).strip())
    except ValueError:
        raise InputError(f"{flag} {value!r}: not an integer; give a seed >= 0, e.g. 0") from None
    if not 0 <= v < 2**63:
        raise InputError(f"{flag} {value}: a seed must be an integer from 0 to 2**63 - 1")
    return v


def robots(value, flag: str = "--robots") -> int:
    """The number of robots of a parametric formation, ``2 .. MAX_ROBOTS``."""
    try:
        v = int(str(value).strip())
    except ValueError:
        raise InputError(f"{flag} {value!r}: not a whole number; give the number of robots, "
                         "e.g. 10") from None
    if not 2 <= v <= MAX_ROBOTS:
        raise InputError(f"{flag} {value}: give a number of robots from 2 to {MAX_ROBOTS}")
    return v


def render_size(w: int, h: int, text: str, flag: str = "--size") -> tuple[int, int]:
    """Check a rendered image size against the stated limits; ``(w, h)``."""
    if w < 64 or h < 48:
        raise InputError(f"{flag} {text!r}: at least 64x48 pixels are needed")
    if w > MAX_RENDER_SIDE or h > MAX_RENDER_SIDE or w * h > MAX_RENDER_PIXELS:
        raise InputError(f"{flag} {text!r}: too large; each side at most {MAX_RENDER_SIDE} and "
                         f"at most {MAX_RENDER_PIXELS} pixels in all (e.g. 4096x4096)")
    return w, h


def focal_px_ok(f: float, width: int, height: int) -> bool:
    """Whether a focal length of ``f`` pixels is plausible for a ``width x height`` image."""
    side = max(int(width), int(height), 1)
    return math.isfinite(f) and FOCAL_RANGE[0] * side <= f <= FOCAL_RANGE[1] * side


def check_focal(K, width: int, height: int, source: str, image: str) -> None:
    """InputError if ``fx`` or ``fy`` of ``K`` is implausible for ``image`` (``source`` named)."""
    for name, f in (("fx", float(K[0][0])), ("fy", float(K[1][1]))):
        if not focal_px_ok(f, width, height):
            side = max(width, height)
            raise InputError(
                f"{source}: {name} = {f:g} px is not a usable focal length for {image} "
                f"({width}x{height}); expected {FOCAL_RANGE[0]:g} to {FOCAL_RANGE[1]:g} times "
                f"the longest side ({FOCAL_RANGE[0] * side:g} to {FOCAL_RANGE[1] * side:g} px)")
