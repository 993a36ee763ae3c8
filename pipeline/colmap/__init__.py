"""The one adapter to pycolmap: every pycolmap call of the pipeline sits in this package, so a
pycolmap API change touches it alone (checked by write-and-reload tests).

- :mod:`.base` — the pixel offset between OpenCV's and COLMAP's conventions, the log level
  (quieted inside the adapter's calls only), the version.
- :mod:`.database` — COLMAP databases: write the pipeline's matches, read COLMAP's or hloc's,
  write a cleaned copy (``clean-db``).
- :mod:`.mapping` — incremental mapping (from scratch, or on the poses of an earlier
  reconstruction) and what is read from a reconstruction (poses,
  similarity between two gauges), model folders.
- :mod:`.sift` — COLMAP's SIFT on an image in memory, COLMAP's matcher and two-view
  verification on a list of pairs (the comm edges).
- :mod:`.known_poses` — robust triangulation with known poses, models of triangulated tracks
  (:mod:`pipeline.evaluation.triangulation`).

May import: pycolmap, the shared words of the root and :mod:`pipeline.inputs` (a database's
tables checked before pycolmap reads them).
"""

from pipeline.colmap.base import COLMAP_PIXEL_OFFSET, quiet_colmap, rigid, version
from pipeline.colmap.database import (
    DatabaseContents,
    calibrated,
    read_database,
    relative_rotations,
    rescale_database,
    write_cleaned_database,
    write_database,
)
from pipeline.colmap.known_poses import (
    build_reconstruction,
    triangulate_known_poses,
    write_points_model,
)
from pipeline.colmap.mapping import (
    MappingSummary,
    incremental_mapping,
    incremental_mapping_with_retry,
    mapping_from_poses,
    model_images,
    model_points,
    model_tracks,
    poses_usable,
    read_model,
    registered_poses,
    rescale_to_files,
    similarity_between,
    undistorted_keypoints,
    write_model,
    write_model_for_files,
)

__all__ = [
    "COLMAP_PIXEL_OFFSET",
    "quiet_colmap",
    "rigid",
    "version",
    "DatabaseContents",
    "calibrated",
    "read_database",
    "relative_rotations",
    "rescale_database",
    "write_cleaned_database",
    "write_database",
    "build_reconstruction",
    "triangulate_known_poses",
    "write_points_model",
    "MappingSummary",
    "incremental_mapping",
    "incremental_mapping_with_retry",
    "mapping_from_poses",
    "poses_usable",
    "model_images",
    "model_points",
    "model_tracks",
    "read_model",
    "registered_poses",
    "rescale_to_files",
    "similarity_between",
    "undistorted_keypoints",
    "write_model",
    "write_model_for_files",
]
