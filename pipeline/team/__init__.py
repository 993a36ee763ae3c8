"""The team: one process per robot over Zenoh.

``TEAM.json`` (:mod:`.teamfile`), the robot program (:mod:`.robot`, ``formation-match
robot``), starting and observing a team (:mod:`.launcher`), the zygote that forks the robots
(:mod:`.zygote`), robots on hosts of their own in network namespaces (:mod:`.netns`) and what the observer makes of the robots' published results
(:mod:`.assemble`).

May import: everything below the stage chain (the root's shared words, :mod:`pipeline.inputs`,
:mod:`pipeline.matching`, :mod:`pipeline.transport`, :mod:`pipeline.consistency`,
:mod:`pipeline.fusion`, :mod:`pipeline.faults`, :mod:`pipeline.evaluation`) and
:mod:`pipeline.stages`; never a runner or a command. The zygote is a program of its own: it
runs the command line's ``robot`` command in every child it forks.
"""
