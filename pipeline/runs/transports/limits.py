"""The team size a transport allows on this machine (its ``MAX_ROBOT_PROCESSES``), refused
before any work: :func:`refuse_over`, shared by the registry's
:func:`pipeline.runs.transports.check_team_size` and the transports themselves."""

from __future__ import annotations

from pipeline.errors import InputError

__all__ = ["refuse_over"]


def refuse_over(name: str, cap: int | None, robots: int, what: str) -> None:
    """InputError when ``robots`` exceeds ``cap`` (None: no limit) on transport ``name``;
    ``what`` says what the robots are (e.g. "cameras in the links file")."""
    if cap is not None and robots > cap:
        raise InputError(f"--transport {name} starts one process per robot on this machine: "
                         f"{robots} {what} would be {robots} processes, at most {cap}; use "
                         "--transport sim, or start the robots on their own hosts "
                         "(formation-match robot --team TEAM.json)")
