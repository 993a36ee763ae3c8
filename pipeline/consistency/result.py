"""What the consistency stage did to every input link, however its robots ran.

The simulator's engines (:mod:`pipeline.consistency.engines.driver`) and the observer of a
team of robot processes (:mod:`pipeline.team.assemble`) both fold the robots' own deletion
logs (:mod:`pipeline.consistency.linklog`) into one :class:`ConsistencyResult`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pipeline.consistency.linklog import merge_link_logs
from pipeline.types import Links

__all__ = ["ConsistencyResult", "result_from_logs"]


@dataclass
class ConsistencyResult:
    """What the distributed stage did to every input link.

    Attributes
    ----------
    links : Links — the input links, ``(L,)``
    deleted : ndarray, (L,) bool
    reason : ndarray, (L,) str — ``'resolution'`` for a link cut by Alg. 1, ``'robot-lost'`` for a
        link cut because the robot at its other end was declared lost, ``''`` if kept
    iteration : ndarray, (L,) int — detection/resolution iteration that cut it (1-based), -1 if kept
    round : ndarray, (L,) int — resolution round of that iteration in which the receiver of the
        request cut it (1-based), -1 if kept
    case : ndarray, (L,) str — for a link cut by resolution, the case that cut it: ``'b'`` or
        ``'c'`` (Alg. 1, line 10), ``'evidence'`` (the evidence rule), ``'sync'`` (the ``sync``
        merge; also a large set of the evidence rule); ``'robot-lost'`` for a link cut because
        its far robot was declared lost; ``''`` if kept
    component : ndarray, (m_total,) int64 — component ``C_q`` built by Alg. 1 for every feature
        (``q`` = global id of its root feature), -1 for features never assigned
    track_label : ndarray, (m_total,) int64 — each robot's own name for the track of each of
        its features (:meth:`Robot.final_tracks`), -1 outside tracks
    stats : dict — ``iterations`` (detection + resolution passes that found conflicts; a
        last detection that finds none ends the loop and is counted in the rounds),
        ``detection_rounds``, ``resolution_rounds`` (totals over all passes),
        ``closing_rounds`` (total of the closing phases; reliable protocol only),
        ``per_iteration`` (one dict per detection; a detection repeated after a loss is
        marked ``repeated`` and keeps the ``iteration`` number of the pass it redoes, which
        the cuts of that pass carry too: ``detection_rounds``, ``t_stop`` (n,) the
        round each robot stopped (Prop. 3.5), ``conflictive_features``, ``conflictive_sets``,
        ``resolution_rounds``, ``last_assignment_round``, ``messages``, ``bytes``),
        ``messages``, ``bytes``, ``messages_by_kind``, ``bytes_by_kind``,
        ``max_robot_memory_bytes`` (peak over robots and rounds of :meth:`Robot.memory_bytes`),
        ``asymmetric_links`` (links between two surviving robots deleted at one end only),
        ``deleted_links``, ``protocol`` (``paper`` or ``reliable``), ``resolution`` (the rule
        that cut: its name in :data:`~pipeline.consistency.rules.RULES`), ``survivors`` (n,) bool
        (robots alive at the end), and ``faults``: what the network injected and its effect
        (``dropped`` messages, ``crashed`` robots with their crash round,
        ``crashed_after_close`` (those of them that crashed after the last closing phase
        began and were not declared lost: they acknowledged every ``closing`` sent to them,
        so their links were kept by the close), ``close_round`` (network round at which the
        last closing phase began, ``None`` without one), ``robots_lost``
        (robot -> neighbours that declared it lost), ``links_cut_robot_lost``,
        ``retransmissions``, ``acks``, ``heartbeats``, ``repeated_detections``)
    """

    links: Links
    deleted: np.ndarray
    reason: np.ndarray
    iteration: np.ndarray
    round: np.ndarray
    case: np.ndarray
    component: np.ndarray
    stats: dict = field(default_factory=dict)
    track_label: np.ndarray | None = None

    def kept(self) -> Links:
        """The links that survived, ``Links`` of length ``(~deleted).sum()``."""
        return self.links.subset(~self.deleted)


def result_from_logs(links: Links, logs, survivors: np.ndarray, component: np.ndarray, *,
                     stats: dict, faults: dict,
                     track_label: np.ndarray | None = None) -> ConsistencyResult:
    """The :class:`ConsistencyResult` of a run, from the robots' own deletion logs.

    ``logs`` as :func:`~pipeline.consistency.linklog.merge_link_logs` takes them;
    ``survivors`` (n,) bool, the robots alive at the end; ``stats`` and ``faults``: the
    figures that depend on how the robots ran (rounds, counters, crashes: the simulator's
    network or the robots' published counters). Added here, read from the logs alike for
    every run: ``deleted_links``, ``asymmetric_links`` (links between two surviving robots
    deleted at one end only), ``survivors``, ``faults`` and its ``links_cut_robot_lost``.
    """
    L = len(links)
    d = merge_link_logs(L, logs)
    both_alive = survivors[links.cam_i] & survivors[links.cam_j] if L else np.zeros(0, bool)
    faults["links_cut_robot_lost"] = int(d["robot_lost"].sum())
    stats.update(asymmetric_links=int(((d["ends_deleted"] == 1) & both_alive).sum()),
                 deleted_links=int(d["deleted"].sum()), survivors=survivors, faults=faults)
    return ConsistencyResult(links=links, deleted=d["deleted"], reason=d["reason"],
                             iteration=d["iteration"], round=d["round"], case=d["case"],
                             component=component, stats=stats, track_label=track_label)
