"""Runners: one per job, each turning a checked configuration into its outputs.

A rendered formation (:mod:`.formation`), a folder of photographs (:mod:`.images`), what the
cleaning jobs write beside their cleaned matches (:mod:`.cleaned`).

May import: everything but :mod:`pipeline.commands` and the command line.
"""
