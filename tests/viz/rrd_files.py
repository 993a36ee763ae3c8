"""A small whole Rerun recording for the tests of this folder that need a ``.rrd`` the viewer
opens (its header and its footer) without a run's content."""

from pathlib import Path


def write_small_recording(path) -> Path:
    """Write a recording of one point to ``path`` (its folder must exist); return its path."""
    import rerun as rr

    rec = rr.RecordingStream("formation-match-test")
    rec.save(path)
    rec.log("point", rr.Points3D([[0.0, 0.0, 0.0]]))
    rec.disconnect()  # writes the footer
    return Path(path)
