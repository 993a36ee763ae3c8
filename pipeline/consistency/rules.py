"""The resolution rules of the consistency stage, by name: the one registry.

After a detection (Aragüés et al., Sec. III) every robot of a conflictive set holds the row
``X_i·(t_i)`` of each of its conflictive features (``robot.conflictive``, ``robot.X``). A
*resolution rule* decides which links the robots of each set cut so that the next detection
finds fewer conflicts, talking only to their neighbours; the loop of Prop. 4.5 repeats
detection and resolution until a detection finds none. ``paper`` is the paper's Alg. 1
(:mod:`.resolution`; over the reliable channel :mod:`.reliable`); ``evidence`` floods each
set's costed links and cuts the same deterministic solution at every robot
(:mod:`.evidence`), after a detection of its own (bounded label flooding, :mod:`.setlists`;
sets beyond its bundle budget merged as ``sync`` merges: :mod:`.engines.evidence_stage`).

``DEFAULT_RESOLUTION`` (``evidence``) is the rule every entry point runs unless told otherwise:
``resolve_conflicts``, the stage functions of :mod:`pipeline.stages`, the runners' configs,
the commands' ``--resolution`` (``run-formations`` keeps ``paper`` to reproduce the paper's
tables) and a ``TEAM.json`` of formations or photographs without ``resolution``. The jobs that
receive links only (``resolve``, ``clean-db``, ``clean-h5``, ``run-landmarks``, a ``TEAM.json``
of links) run
``DEFAULT_LINKS_RESOLUTION`` (``sync``): without poses its decisions are the evidence rule's
greedy merge (plus quadrangle support) and its memory follows the links.

Everything that names a rule reads this registry: the command line's ``--resolution``
choices and help (:func:`pipeline.commands.options.add_resolution_option`), the check of
``TEAM.json`` (:mod:`pipeline.team.teamfile`), the simulator's engines
(:mod:`pipeline.consistency.engines.driver`), the robot program (:mod:`pipeline.team.robot`,
through :mod:`.termination`), the per-link report (:mod:`.linklog`) and the report text
(:mod:`pipeline.evaluation.report`, ``resolve``'s summary).

What a rule provides (:class:`ResolutionRule`)
----------------------------------------------
Its functions are named ``"module:function"`` and imported on first use (as hloc loads its
matchers by name), so that reading the registry loads nothing, and a robot process never
loads the simulator's engines. Every rule runs after the paper's detection (Sec. III), on
the sets it found.

``simulate(robots, network, protocol, iteration, on_round=None) -> dict``
    One resolution pass of all robots of the in-process simulator, each robot stepping on its
    own inbox (the per-robot engine); returns at least ``rounds`` and ``conflictive_sets``.
    On return every robot is ready for the next detection (what it re-examines is set).
``batched`` (optional, same signature and result)
    The same pass of all robots evaluated at once, used by the simulator where the batched
    detection applies (fault-free network, the paper's protocol with delta messages); it must
    give the per-robot engine's results, rounds, messages, bytes and memory (property-test it
    as ``tests/pipeline/consistency/engines/test_batched.py`` does). ``None``: the per-robot
    ``simulate`` runs after the batched detection.
``start(robot, rel, now) -> int``, ``step(robot, rel, inbox, now, phase_round)``, ``done(robot, rel, lost_somewhere) -> bool``, ``finish(robot)``
    The rule run by one robot alone, in its own process (``--transport zenoh``), over the
    reliable channel of ``rel`` (a :class:`~.reliable.ReliableState`): round 0 (returns the
    sets it takes part in), one network round on its inbox, its *done* predicate for the
    termination wave of :mod:`.termination` (``lost_somewhere``: some robot declared a
    neighbour lost in this phase), and what the next detection re-examines after the pass.
``cases``
    The deletion-log codes the rule writes in ``robot.deleted_case`` for a link it cuts, with
    the name each gets in the per-link ``case`` (codes 1–4 are Alg. 1's and the protocol's,
    :mod:`.robot`; take a new one).
``fault_tolerant``
    Whether the rule runs on a faulty network (the simulator's faults, message loss over
    Zenoh). If not, the fault-tolerant Alg. 1 (``paper`` over the reliable protocol) runs
    instead there, and the report says so.
``needs_evidence``
    Whether every robot must hold its links' evidence weights, its keypoints and (where its
    pose is known) its projection before the stage (:func:`.evidence.equip`).
``merge_radius_px``
    The default radius of near-duplicate keypoints merged into one feature with this rule
    (``None``: the co-location radius of :mod:`pipeline.matching.features`).
``detection`` (default ``True``), ``stage``, ``stage_batched``, ``alone``
    A rule with ``detection=False`` is the whole stage: it runs *instead of* the detection
    loop (no Sec. III rows, memory that follows the links). It provides ``stage(robots,
    network, on_round=None) -> dict`` (the simulator: all robots, each on its own inbox;
    returns at least ``rounds``; every robot's ``link_alive``, deletion log and ``component``
    set at the end), optionally ``stage_batched`` (same signature and results, evaluated at
    once where the batched engines apply), and ``alone(robot, transport, protocol, n_robots)
    -> RobotRun`` (one robot in its own process, ending its phases by the termination wave of
    :mod:`.termination`) instead of ``simulate``/``start``/``step``/``done``/``finish``.
``set_lists``
    The rule's own detection floods up to ``B + 1`` ids of each set (:mod:`.setlists`, ``B``
    the bundle budget): the memory guard counts those (:func:`pipeline.budget.
    check_detection_memory`).
``camera_sets``
    The rule's robots hold a bit set of every camera per cluster (``sync``): its memory
    grows with the linked features times the cameras, and the memory guard counts it
    (:func:`pipeline.budget.check_detection_memory`).
``weighs_cycles``
    Whether the rule weighs each link by the triangles (and quadrangles) it closes with the
    other links (:mod:`.cycles`). Such a rule takes the matches as they are: a two-hop vote
    before it (``run-landmarks --refine votes``) only removes links it would have weighed, and
    lowered its pairwise F1 on every CMU hotel input measured (20 / 50 / 101 frames ×
    complete / ``seq:4`` / ring2, guided matching: ``sync`` 1.000 without the votes, 0.967–1.000
    with them; ``evidence`` alike), while Alg. 1, which cuts where its waves meet, needs them
    (``paper-labels`` 0.56–0.95 without, 0.66–1.000 with). ``run-landmarks`` refines by votes
    by default only for a rule without it.
``cuts_as``
    The rule whose cuts this one makes on a fault-free network by construction (another
    protocol for the same decisions, property-tested): reports that compare every rule on
    one input reuse that rule's cuts instead of running both.
``equip``
    With ``needs_evidence``: ``equip(robot, link_weight, keypoints, projection)`` hands a
    robot its own evidence (default :func:`.evidence.equip`).
``help``, ``title``, ``summary``
    Its part of ``--resolution``'s help; what the stage line and reports call it; the text
    of ``resolve``'s summary after ``deleted: N links``, formatted with the counts of
    ``deleted_by_case`` (e.g. ``"(case b: {b}, case c: {c})"``).

A new rule is one module (its robot side; a batched engine under :mod:`.engines` if wanted)
and one :func:`register` call below. A rule kept outside the package registers itself when
its module is imported; naming that module in the environment variable
``FORMATION_MATCH_RULES`` (comma-separated module names) imports it with this registry, in
every process, robot processes included.
"""

from __future__ import annotations

import importlib
import os
from dataclasses import dataclass, field

__all__ = ["ResolutionRule", "RULES", "register", "unregister", "get_rule", "rule_names",
           "rule_for_network", "case_names", "deleted_cases", "ALG1_CASES",
           "DEFAULT_RESOLUTION", "DEFAULT_LINKS_RESOLUTION"]

#: the rule every entry point runs unless told otherwise (the Python API, the stage functions,
#: the runners' configs, the commands, a TEAM.json of formations or photographs without
#: ``resolution``); ``run-formations``
#: reproduces the paper's tables with ``paper``. Registered below.
DEFAULT_RESOLUTION = "evidence"
#: the rule of the jobs that receive links only (``resolve``, ``clean-db``, ``clean-h5``,
#: ``run-landmarks``, a TEAM.json of links): no camera poses, so the evidence rule's geometric tests cannot run and
#: its decisions are the greedy merge ``sync`` computes too, at a higher cost (its detection
#: floods up to ``B + 1`` ids per feature: a 101-frame CMU hotel input, 326 MB peak against
#: sync's 317 MB, 732 MB on the wire against 308 MB); ``sync`` also counts quadrangles on
#: every set (a ring2 team with swapped matches: F1 0.92 -> 1.00 at 100 cameras). Measured by
#: ``bench/multiway.py``.
DEFAULT_LINKS_RESOLUTION = "sync"

#: the cases of Alg. 1 every report lists (line 10: (b) the feature is already in another
#: component, (c) its camera already is); the fault-tolerant fallback cuts only these
ALG1_CASES = ("b", "c")

#: environment variable naming modules that register more rules (module docstring)
PLUGINS_ENV = "FORMATION_MATCH_RULES"

_HOOKS = ("simulate", "batched", "start", "step", "done", "finish", "stage", "stage_batched",
          "alone", "equip")
_LOOP_HOOKS = ("simulate", "start", "step", "done", "finish")
_STAGE_HOOKS = ("stage", "alone")


@dataclass(frozen=True)
class ResolutionRule:
    """One resolution rule (the module docstring says what each field is)."""

    name: str
    help: str
    title: str
    summary: str
    cases: dict
    simulate: str | None = None
    start: str | None = None
    step: str | None = None
    done: str | None = None
    finish: str | None = None
    batched: str | None = None
    detection: bool = True
    stage: str | None = None
    stage_batched: str | None = None
    alone: str | None = None
    equip: str | None = "pipeline.consistency.evidence:equip"
    fault_tolerant: bool = False
    needs_evidence: bool = False
    merge_radius_px: float | None = None
    cuts_as: str | None = None
    set_lists: bool = False
    camera_sets: bool = False
    weighs_cycles: bool = False
    _loaded: dict = field(default_factory=dict, compare=False, repr=False)

    def hook(self, name: str):
        """The function of field ``name`` (``simulate``, ``batched``, ``start``, ``step``,
        ``done``, ``finish``), imported on first use; ``None`` for an absent ``batched``."""
        if name not in _HOOKS:
            raise KeyError(f"resolution rule hook {name!r}: one of {', '.join(_HOOKS)}")
        if name not in self._loaded:
            path = getattr(self, name)
            if path is None:
                self._loaded[name] = None
            else:
                module, _, function = path.partition(":")
                self._loaded[name] = getattr(importlib.import_module(module), function)
        return self._loaded[name]


RULES: dict[str, ResolutionRule] = {}


def register(rule: ResolutionRule) -> ResolutionRule:
    """Add ``rule`` to the registry (ValueError if its name or a case code is taken, or a
    function its kind needs is missing)."""
    needed = _LOOP_HOOKS if rule.detection else _STAGE_HOOKS
    missing = [h for h in needed if getattr(rule, h) is None]
    if missing:
        raise ValueError(f"resolution rule {rule.name!r}: no {', '.join(missing)} (a rule "
                         f"{'after' if rule.detection else 'without'} detection needs them)")
    if rule.name in RULES:
        raise ValueError(f"resolution rule {rule.name!r} is already registered")
    taken = {code for r in RULES.values() for code in r.cases}
    if taken & set(rule.cases):
        raise ValueError(f"resolution rule {rule.name!r}: case codes {sorted(taken & set(rule.cases))} "
                         "are another rule's")
    RULES[rule.name] = rule
    return rule


def unregister(name: str) -> None:
    """Remove a rule from the registry (tests register toy ones)."""
    del RULES[name]


def rule_names() -> tuple[str, ...]:
    """The registered rules' names, in registration order."""
    return tuple(RULES)


def get_rule(name: str) -> ResolutionRule:
    """The registered rule ``name``.

    Raises
    ------
    InputError
        No rule of that name.
    """
    from pipeline.errors import InputError

    if name not in RULES:
        raise InputError(f"resolution {name!r}: choose one of {', '.join(RULES)}")
    return RULES[name]


def rule_for_network(name: str, faulty: bool) -> ResolutionRule:
    """The rule that runs when ``name`` is asked for: itself, or on a faulty network the
    fault-tolerant Alg. 1 when the rule is not fault-tolerant."""
    rule = get_rule(name)
    return RULES["paper"] if faulty and not rule.fault_tolerant else rule


def deleted_cases(name: str) -> tuple[str, ...]:
    """The ``case`` names a report counts the cuts of rule ``name`` by: Alg. 1's (b) and (c)
    (the fault-tolerant fallback), then the rule's own."""
    return tuple(dict.fromkeys((*ALG1_CASES, *get_rule(name).cases.values())))


def case_names() -> dict[int, str]:
    """Deletion-log code → per-link ``case`` name of every cut a rule decides."""
    return {code: case for rule in RULES.values() for code, case in rule.cases.items()}


# codes of robot.py (CASE_B, CASE_C) and evidence.py (CASE_EVIDENCE); a rule's cases are
# written here literally so that reading the registry imports no robot code
register(ResolutionRule(
    name="paper",
    help="paper = Alg. 1 of Aragues et al.",
    title="detection (Sec. III) + resolution (Alg. 1) of Aragüés et al.",
    summary="(case b: {b}, case c: {c})",
    cases={1: "b", 2: "c"},
    simulate="pipeline.consistency.engines.phases:run_resolution_phase",
    batched="pipeline.consistency.engines.batched:run_resolution",
    start="pipeline.consistency.reliable:start_resolution_reliable",
    step="pipeline.consistency.reliable:resolution_round",
    done="pipeline.consistency.reliable:resolution_done",
    finish="pipeline.consistency.resolution:finish_resolution",
    fault_tolerant=True))
register(ResolutionRule(
    name="evidence",
    help="evidence = the robots of each set agree on the cut that keeps the best-supported "
         "links",
    title="detection by bounded label flooding + the evidence-aware resolution (robots of a "
          "set agree on the cut that keeps the best-supported links; sets beyond the bundle "
          "budget by the distributed greedy merge)",
    summary="by the evidence rule",
    # the cuts of the small sets and of the large sets' merge alike
    cases={5: "evidence"},
    detection=False,
    stage="pipeline.consistency.engines.evidence_stage:run_evidence_stage",
    stage_batched="pipeline.consistency.engines.evidence_stage:run_evidence_stage_batched",
    alone="pipeline.consistency.alone:run_evidence_locally",
    set_lists=True,
    needs_evidence=True,
    weighs_cycles=True,
    merge_radius_px=2.0))
register(ResolutionRule(
    name="sync",
    help="sync = distributed multi-way matching: the robots merge features into landmarks "
         "by the best-supported links, never two of one camera (no detection)",
    title="distributed multi-way matching (Borůvka rounds of the constrained greedy merge, "
          "no detection)",
    summary="by the multi-way matching",
    cases={6: "sync"},
    detection=False,
    stage="pipeline.consistency.engines.sync_batched:run_sync",
    stage_batched="pipeline.consistency.engines.sync_batched:run_sync_batched",
    alone="pipeline.consistency.sync_alone:run_sync_locally",
    equip="pipeline.consistency.sync:equip_robot",
    camera_sets=True,
    needs_evidence=True,
    weighs_cycles=True,
    merge_radius_px=2.0))
register(ResolutionRule(
    name="paper-labels",
    help="paper-labels = Alg. 1 after a detection by label flooding (the paper's outcome, "
         "memory that follows the links)",
    title="detection by label flooding (the outcome of Sec. III) + resolution (Alg. 1) of "
          "Aragüés et al.",
    summary="(case b: {b}, case c: {c})",
    # its cuts are Alg. 1's cases (b) and (c), codes of the paper rule (counted for every rule)
    cases={},
    detection=False,
    stage="pipeline.consistency.engines.paper_labels:run_paper_labels",
    alone="pipeline.consistency.alone:run_paper_labels_locally",
    cuts_as="paper"))
for _module in filter(None, (m.strip() for m in os.environ.get(PLUGINS_ENV, "").split(","))):
    importlib.import_module(_module)
