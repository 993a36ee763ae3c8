"""Helpers of the namespace tests: a team of robot programs, one per host of a
:class:`pipeline.team.netns.NetnsRig`, and what their result files say."""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from pipeline.consistency.centralized import is_conflict_free
from pipeline.team.teamfile import DEFAULT_OPTIONS, RobotEntry, Team, parse_team, write_team
from pipeline.types import Links

ROOT = Path(__file__).resolve().parents[3]


def rig_team(rig, name: str, data: dict, options: dict | None = None,
             robot_options: dict | None = None) -> Team:
    """A team whose robot ``i`` listens on the rig's address of host ``i`` (no observer)."""
    robots = [RobotEntry(i, rig.endpoint(i)) for i in range(rig.n)]
    t = Team(name, robots, np.asarray(rig.edges, np.int64), data,
             {**DEFAULT_OPTIONS, **(options or {})}, dict(robot_options or {}))
    return parse_team(t.to_json())


def start_team(rig, team: Team, workdir: Path, ids=None) -> dict:
    """Start robot programs on their hosts (default all); returns ``{id: result path}``."""
    workdir.mkdir(parents=True, exist_ok=True)
    team_path = write_team(workdir / "TEAM.json", team)
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1",
           "OPENBLAS_NUM_THREADS": "1", "PYTHONUNBUFFERED": "1"}
    out = {}
    for i in (range(team.n) if ids is None else ids):
        res = workdir / f"robot{i}.json"
        log = open(workdir / f"robot{i}.log", "wb")  # noqa: SIM115 - closed by the process end
        rig.start(i, [sys.executable, "-m", "pipeline", "robot", "--team", str(team_path),
                      "--id", str(i), "--result", str(res)], stdout=log, stderr=log, env=env,
                  cwd=str(ROOT))
        out[i] = res
    return out


def wait_for_line(path: Path, text: str, timeout_s: float) -> bool:
    """True once ``text`` appears in the file (polled), False after ``timeout_s``."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if path.exists() and text in path.read_text(errors="replace"):
            return True
        time.sleep(0.05)
    return False


def results(paths: dict) -> dict:
    """The result documents that were written, by robot id."""
    return {i: json.loads(p.read_text()) for i, p in paths.items() if p.exists()}


def team_links(res: dict) -> tuple[dict, dict]:
    """Each link's status as each end reports it: ``{(i, r, j, s): {robot: alive}}`` and
    ``{(i, r, j, s): {robot: deleted_case}}``, links stored with ``i < j``."""
    alive, case = {}, {}
    for i, doc in res.items():
        L = doc["links"]
        for k, r, s, a, c in zip(L["link_nbr"], L["link_r"], L["link_s"], L["link_alive"],
                                 L["deleted_case"], strict=True):
            key = (i, r, k, s) if i < k else (k, s, i, r)
            alive.setdefault(key, {})[i] = bool(a)
            case.setdefault(key, {})[i] = int(c)
    return alive, case


def kept_conflict_free(res: dict) -> bool:
    """Are the links kept by both ends (one end only when the other wrote no result)
    conflict-free?"""
    alive, _ = team_links(res)
    kept = [k for k, v in alive.items() if all(v.values())]
    m = next(iter(res.values()))["features_per_camera"]
    return is_conflict_free(m, Links([k[0] for k in kept], [k[1] for k in kept],
                                     [k[2] for k in kept], [k[3] for k in kept]))
