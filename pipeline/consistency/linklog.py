"""Per-link decisions from the robots' own deletion logs (reporting only, never robot code).

Each robot logs, for every row of its link table, whether it still holds the link and, if
not, why (Alg. 1 case (b)/(c) as the receiver of a request, on a reject, by another
resolution rule of :mod:`.rules` such as the evidence rule, or ``robot-lost``),
in which iteration and round. A link is deleted when either end deleted it; its reason is
``resolution`` unless the only cut was a ``robot-lost`` one; its round and case are those of
the end that cut it as the receiver of a request (the earlier one if both did).
"""

from __future__ import annotations

import numpy as np

from pipeline.consistency.robot import ROBOT_LOST
from pipeline.consistency.rules import case_names

__all__ = ["merge_link_logs"]


def merge_link_logs(n_links: int, logs) -> dict:
    """Fold the robots' logs into per-link arrays.

    Parameters
    ----------
    n_links : int — ``L``
    logs : iterable of ``(link_index, link_alive, deleted_case, deleted_round,
        deleted_iteration)``, one per robot whose log is known, each array ``(L_i,)``;
        ``link_index`` maps the robot's rows to the links ``0..L-1``

    Returns
    -------
    dict of ``(L,)`` arrays: ``deleted`` bool, ``reason`` str, ``iteration``, ``round``,
    ``case`` str, ``ends_deleted`` int (0, 1 or 2), ``robot_lost`` bool
    """
    L = int(n_links)
    logs = list(logs)
    iteration = np.full(L, -1, dtype=np.int64)
    round_ = np.full(L, -1, dtype=np.int64)
    names = case_names()  # deletion-log code -> case, of every resolution rule
    case = np.full(L, "", dtype=f"<U{max(map(len, names.values()), default=1)}")
    if logs:
        li = np.concatenate([np.asarray(x[0], dtype=np.int64) for x in logs])
        alive = np.concatenate([np.asarray(x[1], dtype=bool) for x in logs])
        dcase = np.concatenate([x[2] for x in logs])
        dround = np.concatenate([x[3] for x in logs]).astype(np.int64)
        diter = np.concatenate([x[4] for x in logs]).astype(np.int64)
    else:
        li = dround = diter = np.zeros(0, dtype=np.int64)
        alive, dcase = np.zeros(0, dtype=bool), np.zeros(0, dtype=np.int8)
    ends_deleted = np.bincount(li[~alive], minlength=L).astype(np.int64)
    lost_end = np.zeros(L, dtype=bool)
    lost_end[li[dcase == ROBOT_LOST]] = True
    decided = np.flatnonzero(np.isin(dcase, list(names)))
    if decided.size:
        # if both ends cut the link as receivers (crossing requests), keep the earlier round
        # (on a tie, the end whose log comes first)
        order = decided[np.lexsort((decided, dround[decided], li[decided]))]
        first = order[np.r_[True, li[order][1:] != li[order][:-1]]]
        g = li[first]
        iteration[g] = diter[first]
        round_[g] = dround[first]
        for code, name in names.items():
            case[g[dcase[first] == code]] = name
    deleted = ends_deleted > 0
    reason = np.where(deleted, "resolution", "").astype("<U10")
    # a link whose far end was declared lost: robot-lost, unless Alg. 1 had already cut it
    robot_lost = deleted & lost_end & (case == "")
    reason[robot_lost] = "robot-lost"
    for li, _, dcase, dround, diter in logs:
        li = np.asarray(li, dtype=np.int64)
        lost = np.flatnonzero(dcase == ROBOT_LOST)
        g = li[lost]
        sel = robot_lost[g] & ((round_[g] < 0) | (iteration[g] < 0))
        iteration[g[sel]] = diter[lost[sel]]
        round_[g[sel]] = dround[lost[sel]]
    return dict(deleted=deleted, reason=reason, iteration=iteration, round=round_, case=case,
                ends_deleted=ends_deleted, robot_lost=robot_lost)
