"""Shared by the zygote tests of this folder: a small links input with two conflictive sets
over four cameras (robots must talk to cut them) and the live children of a process."""

from pathlib import Path

#: links file text: two conflictive sets over four cameras
LINKS = ("cam_i,feat_i,cam_j,feat_j\n0,0,1,0\n1,0,2,0\n0,1,2,0\n2,1,3,0\n3,0,0,2\n"
         "1,1,3,0\n")
FPC = [3, 2, 2, 1]
EDGES = [[0, 1], [1, 2], [0, 2], [2, 3], [0, 3], [1, 3]]


def links_team(folder, name: str, options: dict | None = None):
    """A launcher's team of four robots reading :data:`LINKS` (written to ``folder/in.csv``)
    on :data:`EDGES`, with ``options``; returns the team and the links file."""
    from pipeline.team.launcher import make_team

    links = Path(folder) / "in.csv"
    links.write_text(LINKS)
    data = {"kind": "links", "links": str(links), "features_per_camera": FPC}
    return make_team(name, EDGES, data, options, n=4), links


def children(pid: int) -> list[int]:
    """Live (not zombie) processes whose parent is ``pid``."""
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid and fields[0] != "Z":
            out.append(int(stat.parent.name))
    return out
