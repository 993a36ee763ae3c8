"""formation-match: consistent, decentralized multi-camera data association.

Stages (see docs/DESIGN.md): ``matching`` (features, pairs) → ``association`` → ``consistency``
(Aragüés et al., detection Sec. III + a resolution rule, the evidence rule by default,
``consistency.rules.DEFAULT_RESOLUTION``) → ``fusion`` (Montijano et al., distributed RANSAC
with dynamic voting) → ``evaluation`` (triangulation, metrics, report). The folders are the
architecture, bottom to top (docs/architecture.md, checked by
tests/pipeline/test_architecture.py): the shared words of this root (``errors``, ``types``,
``validate``, ``progress``, ``outcome``, ``outputs``, ``runfolder``) → ``inputs`` → ``colmap``
→ the graphs (``association``, ``commgraph``, ``budget``) → ``transport`` → ``matching`` →
``consistency`` → ``fusion`` → ``faults`` → ``evaluation`` → ``stages`` (the stage chain) →
``team`` → ``runs`` → ``commands`` → the programs (``__main__``, ``team.zygote``).

May import: a module imports its own layer and the layers below it, never one above.
"""

__version__ = "0.1.0"
