"""What a transport's jobs hand back to their runner (:mod:`pipeline.runs.transports`)."""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["FormationRobots", "ImagesRobots"]


@dataclass
class FormationRobots:
    """What the robots of a rendered formation produced, for the evaluation and the outputs.

    Attributes
    ----------
    formation : data_synth.Formation — the views and the comm graph (with ground truth)
    features : list[Features] — per camera
    matches : list[PairMatches] — per comm edge
    cleaning : CleaningResult — the consistency (and fusion) stages' decisions
    extra : dict — sections the transport adds to ``report.json`` (e.g. ``team``)
    """

    formation: object
    features: list
    matches: list
    cleaning: object
    extra: dict = field(default_factory=dict)


@dataclass
class ImagesRobots:
    """What the robots of a folder of photographs produced (``cleaning`` None: the runner
    runs the consistency stage itself; ``team`` the report's ``team`` section or None)."""

    features: list
    matches: list
    links: object
    cleaning: object = None
    team: dict | None = None
