"""Is a finished run what the user asked for? Checks of the final result, for every command.

The consistency stage promises a conflict-free association (Aragüés et al., Prop. 4.5). Under
injected faults (crashed robots, heavy message loss) the stage can end without keeping that
promise, or keep it only by cutting everything; a run must then not look like a success.
:func:`flag_result` checks a finished report centrally (the counts of
:func:`pipeline.association.count_conflicts` on the final links, already in the report's
``after`` section) and adds to it, only when something is wrong:

- ``conflict_free: false`` — conflictive sets remain in the written result;
- ``warnings`` — a list of ``{"code", "message"}``: ``not-conflict-free``,
  ``all-links-cut`` (every input link was cut), ``robots-lost`` (robots crashed, were killed
  or never started: their links are cut or left unchecked), ``robots-lost-without-crash`` (robots were
  declared lost from silence although they never crashed: the message loss defeated the
  timeouts; over zenoh, robot processes that ran to their end but were written off by a
  neighbour, a partition or a round limit), ``robots-unreported`` (over zenoh, robots that
  ran to their end with their neighbours but whose results never reached the observer),
  ``pairs-unmatched`` (over zenoh, comm-graph pairs never matched: a neighbour written off
  before the features crossed),
  ``no-features`` (images where no feature was found, named),
  ``quality-reversed`` (``resolve``: the links the triangles refute carry the higher quality,
  :mod:`pipeline.evaluation.quality`), ``quality-scale`` (``resolve``: qualities above 1,
  another scale than ``1 - Lowe ratio``), ``logged`` (each warning the run printed on stderr
  before its report was made, within :func:`recording_warnings`: files of the input left
  out, identical images, a comm graph in pieces, …; so the report keeps what the terminal
  showed).

:func:`exit_status` prints them on stderr and gives the exit code. The rule: ``3`` when the
result is not conflict-free (it is still written, and flagged), else ``0``; warnings alone do
not change the exit code. A clean run's report is left byte-identical.
"""

from __future__ import annotations

import contextlib
import logging
import sys

from pipeline.errors import listed
from pipeline.progress import counted

__all__ = ["EXIT_NOT_CONFLICT_FREE", "flag_result", "flag_online", "NO_LINKS_WHY",
           "merge_radius_why", "exit_status", "recording_warnings"]

#: Exit code of a run whose written result still holds conflictive sets.
EXIT_NOT_CONFLICT_FREE = 3


def _warning(code: str, message: str) -> dict:
    return {"code": code, "message": message}


#: the warnings the program's loggers printed within :func:`recording_warnings` (None:
#: outside it)
_printed: list[str] | None = None


class _Recorder(logging.Handler):
    """Keeps the message of every warning (and error) a ``pipeline`` logger prints."""

    def __init__(self):
        super().__init__(level=logging.WARNING)

    def emit(self, record: logging.LogRecord) -> None:
        if _printed is not None:
            text = record.getMessage()
            _printed.append(text.removeprefix("warning: "))


@contextlib.contextmanager
def recording_warnings():
    """Within the block (a command's run), the warnings the ``pipeline`` loggers print on
    stderr are also kept: :func:`flag_result` and :func:`flag_online` add those printed so far
    to the report, code ``logged`` (not printed again by :func:`exit_status`)."""
    global _printed
    log = logging.getLogger("pipeline")
    handler, before = _Recorder(), _printed
    _printed = []
    log.addHandler(handler)
    try:
        yield
    finally:
        log.removeHandler(handler)
        _printed = before


def _logged() -> list[dict]:
    """The ``logged`` warnings: each one printed so far within :func:`recording_warnings`."""
    return [_warning("logged", text) for text in dict.fromkeys(_printed or ())]


#: one-sided p-value under which a report's ``quality_evidence`` (the links' quality against
#: their cycles, :mod:`pipeline.evaluation.quality`) is warned of as reversed
REVERSED_P = 1e-3

#: why an input may hold no link, by default (runs that match images)
NO_LINKS_WHY = "images too small, too few features, or no overlap between neighbours"


def merge_radius_why(radius: float | None, size: tuple[int, int]) -> str:
    """The clause a ``no-links`` warning adds when ``--merge-radius`` is wide enough (a tenth
    of the image's shorter side or more, e.g. ``--merge-radius 1000``) to have merged each
    image's keypoints into a few features; ``""`` otherwise."""
    if radius is None or radius < 0.1 * min(size):
        return ""
    return f", or a --merge-radius of {radius:g} px merging each image's keypoints"


def _every(n: int, noun: str) -> str:
    """``the one link`` or ``every one of the 3 links``, as a warning says them."""
    return f"the one {noun}" if n == 1 else f"every one of the {counted(n, noun)}"


def flag_result(report: dict, names: list[str] | None = None,
                no_links_why: str = NO_LINKS_WHY) -> dict:
    """Add ``conflict_free: false`` and ``warnings`` to ``report`` (in place) where due.

    Parameters
    ----------
    report : a command's summary / ``report.json`` dict with ``after`` (conflict counts of the
        final links) and, where present, ``links`` or ``before.links`` (input links),
        ``faults`` (:func:`pipeline.faults.fault_report`), ``features_per_camera``
    names : image names in camera order (for ``no-features``); default ``camera K``
    no_links_why : the likely causes the ``no-links`` warning names (what the input was)

    Returns
    -------
    report (the same dict)
    """
    warnings = []
    after = report.get("after") or {}
    # a team run of processes (zenoh) keeps its faults beside the stage's other details
    faults = (report.get("faults")
              or ((report.get("resolution") or {}).get("details") or {}).get("faults") or {})
    left = int(after.get("conflictive_sets") or 0)
    if left:
        report["conflict_free"] = False
        crashed = sorted(faults.get("crashed", {}), key=int)
        why = f" (robot(s) {_listed(crashed)} crashed before it ended)" if crashed else ""
        warnings.append(_warning(
            "not-conflict-free",
            f"the result is not conflict-free: {left} conflictive set(s) with "
            f"{after.get('conflictive_features')} feature(s) remain after the consistency "
            f"stage{why}; do not use it as a clean association"))
    total = report.get("links")
    if not isinstance(total, int):
        total = (report.get("before") or {}).get("links")
    kept = after.get("links")
    # rows an input had already deleted (a run-output links.csv given to resolve) stay as
    # they were: when they are all it holds, this run had no link to associate, and cut none
    active = total - int(report.get("previously_deleted") or 0) if isinstance(total, int) \
        else total
    if active == 0:
        warnings.append(_warning(
            "no-links", "the input holds no link between two images: there is nothing to "
                        f"associate ({no_links_why})"))
    if active and kept == 0:
        warnings.append(_warning("all-links-cut", f"{_every(total, 'input link')} was cut; the "
                                                  "result holds no association"))
    gone = {str(k) for k in faults.get("crashed", {})}
    team = report.get("team") or {}
    if isinstance(team.get("robots"), dict):  # a team of processes: those without a result
        gone |= {str(k) for k in team.get("lost") or []}
        ran = {str(k) for k, v in team["robots"].items() if isinstance(v, dict) and "rounds" in v}
        gone |= {str(k) for k in faults.get("robots_lost", {})} - ran
    unmatched = team.get("unmatched_pairs") or []
    if unmatched:
        pairs = ", ".join(f"{a}-{b}" for a, b in unmatched)
        warnings.append(_warning(
            "pairs-unmatched",
            f"{len(unmatched)} image pair(s) of the comm graph were never matched ({pairs}): "
            "a robot wrote its neighbour off before their features crossed (each robot's "
            "counters name why); their links are missing from the result, not cut, so no "
            "count of cut links includes them"))
    unheard = {str(k) for k in team.get("unreported") or []}
    gone -= unheard
    if unheard:
        warnings.append(_warning(
            "robots-unreported",
            f"robot(s) {', '.join(sorted(unheard, key=int))} ran to their end with their "
            "neighbours (none wrote them off), but their results never reached the observer "
            "(check the observer's network path to them): their links were decided by both "
            "ends as in a whole run; their own counters and fusion estimates are missing from "
            "the report"))
    if gone:
        ids = sorted(gone, key=int)
        cut = faults.get("links_cut_robot_lost")
        warnings.append(_warning(
            "robots-lost",
            f"robot(s) {_listed(ids)} crashed, were killed or never took part before the "
            f"consistency stage ended; {cut if cut is not None else 'their'} link(s) to them "
            "were cut as robot-lost by the survivors, and a link between two of them keeps the "
            "status it had when they stopped (checked by no robot after that): rerun without "
            "the fault for a whole association"))
    false_lost = sorted({str(k) for k in faults.get("robots_lost", {})} - gone, key=int)
    if false_lost:
        dropped = faults.get("messages_dropped", faults.get("dropped"))
        why = (f"{dropped} messages dropped" if "robots" not in team else
               f"{dropped} messages dropped; they ran to their end, written off by a silent or "
               "cut-off neighbour or a round limit: each robot's counters name why")
        warnings.append(_warning(
            "robots-lost-without-crash",
            f"robot(s) {_listed(false_lost)} were declared lost by their neighbours although "
            f"they never crashed ({why}); "
            f"{faults.get('links_cut_robot_lost')} link(s) were cut as robot-lost"))
    qe = report.get("quality_evidence") or {}
    if qe.get("p_reversed") is not None and qe["p_reversed"] < REVERSED_P:
        warnings.append(_warning(
            "quality-reversed",
            f"the links' quality looks reversed: the {qe['refuted']} links the triangles refute "
            f"have higher quality than the {qe['confirmed']} they confirm (AUC "
            f"{qe['auc']:.2f}, one-sided p {qe['p_reversed']:.1e}); the merge rules read quality "
            "as growing with confidence (e.g. 1 - Lowe ratio): give a similarity, not a "
            "distance" + ("" if qe.get("read_by_rule", True) else
                          f" (the rule that ran, {report.get('resolution_method')}, does not "
                          "read the quality: this run's cuts do not depend on it)")))
    if qe.get("above_one") and qe.get("read_by_rule", True):
        warnings.append(_warning(
            "quality-scale",
            f"{qe['above_one']} of the links' qualities are above 1: the merge rules read "
            "quality as 1 - Lowe ratio (at most 1) and count every quality above 0.99 as "
            "near-certain, so the order of these barely weighs; rescale the quality to [0, 1] "
            "(e.g. score / max score)"))
    warnings += _no_features(report, names) + _logged()
    if warnings:
        report["warnings"] = warnings
    return report


#: images or robots a warning names (a formation of 1000 robots, most beside the facade,
#: named 731 images on one line; --drop-prob 0.9 every robot of a team of 40)
NAMES_SHOWN = 20


def _listed(names: list[str]) -> str:
    """``names`` comma-separated, or the first :data:`NAMES_SHOWN` and how many more
    (:func:`pipeline.errors.listed`)."""
    return listed(names, NAMES_SHOWN, last=", ")


def _no_features(report: dict, names: list[str] | None, void=()) -> list[dict]:
    """The ``no-features`` warning of the images of ``report["features_per_camera"]`` that
    hold none (but the ``void`` ones, which have a warning of their own), or nothing."""
    m = report.get("features_per_camera")
    void = set(void)
    empty = [] if m is None else [k for k, v in enumerate(m) if int(v) == 0 and k not in void]
    if not empty:
        return []
    shown = _listed([names[k] if names else f"camera {k}" for k in empty])
    more = " (features_per_camera in report.json has each image's count)" \
        if len(empty) > NAMES_SHOWN else ""
    return [_warning("no-features", f"no features found in {len(empty)} image(s): "
                     f"{shown}{more} (blank, too small or too narrow); they take no part")]


def flag_online(report: dict, no_links_why: str = NO_LINKS_WHY,
                names: list[str] | None = None) -> dict:
    """:func:`flag_result` for an online run's report (``steps``, ``final``,
    ``conflict_free_every_step``): ``no-links`` (no link in any step), ``all-links-cut``,
    ``not-conflict-free`` (a step ended with conflictive sets: ``conflict_free: false``),
    ``no-features`` (frames of ``features_per_camera`` holding none, named by ``names``),
    ``frames-void`` (frames whose robot process the step's matching lost twice: the steps'
    ``match_frames_void``; named there, not under ``no-features``)."""
    warnings = []
    steps = report.get("steps", [])
    left = [k for k, s in enumerate(steps) if s.get("conflictive_sets_after")]
    if left:
        report["conflict_free"] = False
        warnings.append(_warning(
            "not-conflict-free", f"the association was not conflict-free after step(s) "
            f"{', '.join(map(str, left[:5]))}{', ...' if len(left) > 5 else ''}; do not use it "
            "as a clean association"))
    final = report.get("final", {})
    total = int(final.get("links", 0))
    if total == 0:
        warnings.append(_warning(
            "no-links", f"no link in {counted(len(steps), 'step')}: there is nothing to associate "
                        f"({no_links_why})"))
    elif int((final.get("online") or {}).get("kept", -1)) == 0:
        warnings.append(_warning("all-links-cut", f"{_every(total, 'link')} was cut; the "
                                                  "result holds no association"))
    void = sorted({int(g) for s in steps for g in s.get("match_frames_void", ())})
    if void:
        shown = [names[g] if names else f"frame {g}" for g in void]
        warnings.append(_warning(
            "frames-void", f"{len(void)} frame(s) never reached the association: "
            f"{', '.join(shown[:10])}{', ...' if len(shown) > 10 else ''} (their robot "
            "process was lost by its step's matching twice: no features, no links; the "
            "other frames went on without them)"))
    warnings += _no_features(report, names, void) + _logged()
    if warnings:
        report["warnings"] = warnings
    return report


def exit_status(report: dict, stream=None) -> int:
    """Print the report's warnings on ``stream`` (stderr); the exit code (module rule)."""
    stream = stream if stream is not None else sys.stderr
    for w in report.get("warnings", []):
        if w["code"] == "logged":  # printed when it arose
            continue
        kind = "error" if w["code"] == "not-conflict-free" else "warning"
        print(f"{kind}: {w['message']}", file=stream)
    return EXIT_NOT_CONFLICT_FREE if report.get("conflict_free") is False else 0
