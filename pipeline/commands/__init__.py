"""CLI commands: one module per command, each with ``add_arguments(parser)`` and ``run(args)``.

A command parses and checks its options (those several commands share are in :mod:`.options`,
whose variants, ``--resolution`` and ``--transport``, are read from their registries), calls
its job's runner (:mod:`pipeline.runs`) and prints; commands never import each other.

May import: everything but the command line itself (:mod:`pipeline.__main__`).
"""
