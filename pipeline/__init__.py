"""formation-match: consistent, decentralized multi-camera data association.

Stages (one module each, see docs/DESIGN.md): ``features`` → ``matching`` → ``association`` →
``consistency`` (Aragüés et al., detection Sec. III + resolution Alg. 1) → ``fusion``
(Montijano et al., distributed RANSAC with dynamic voting) → ``triangulation`` → ``evaluate``.
"""

__version__ = "0.1.0"
