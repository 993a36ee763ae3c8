"""``observe`` of a links team whose links file has a quality column writes it as the last
column of its ``links.csv``, as ``resolve`` of the same file does: it wrote none, so its output
given back to ``resolve`` weighed every link alike."""

import os
import subprocess
import sys

import numpy as np

from pipeline.__main__ import main


def _team_of(tmp_path, links_csv, n):
    from pipeline.team.launcher import make_team
    from pipeline.team.teamfile import write_team

    edges = [[i, j] for i in range(n) for j in range(i + 1, n)]
    team = make_team("quality", edges, {"kind": "links", "links": str(links_csv),
                                        "features_per_camera": [8] * n},
                     {"resolution": "evidence", "start_timeout_s": 120.0}, n=n)
    return write_team(tmp_path / "TEAM.json", team)


def _observe(tmp_path, links_csv, n) -> list[str]:
    """``observe`` of a team of ``n`` robots started by hand on ``links_csv``: the lines of
    its ``links.csv``."""
    path = _team_of(tmp_path, links_csv, n)
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    procs = [subprocess.Popen([sys.executable, "-m", "pipeline", "robot", "--team", str(path),
                               "--id", str(i)], stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL, env=env) for i in range(n)]
    try:
        assert main(["observe", "--team", str(path), "--out", str(tmp_path / "obs"),
                     "--timeout", "300"]) == 0
    finally:
        for p in procs:
            try:
                p.wait(timeout=60)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
    return (tmp_path / "obs" / "links.csv").read_text().splitlines()


def _links_file(tmp_path, quality: bool):
    rng = np.random.default_rng(7)
    rows, seen = [], set()
    while len(rows) < 20:  # of at most 24 (3 camera pairs, 8 features each)
        i, j = sorted(rng.choice(3, 2, replace=False).tolist())
        r, s = int(rng.integers(8)), int(rng.integers(8))
        if (i, r, j) not in seen and (j, s, i) not in seen:
            seen |= {(i, r, j), (j, s, i)}
            rows.append((i, r, j, s))
    rows.sort()
    q = rng.uniform(0.05, 0.95, len(rows))  # full float64 digits: they must come back alike
    path = tmp_path / "in.csv"
    path.write_text(("cam_i,feat_i,cam_j,feat_j,quality\n" if quality
                     else "cam_i,feat_i,cam_j,feat_j\n") + "".join(
        f"{a},{b},{c},{d}" + (f",{x!r}" if quality else "") + "\n"
        for (a, b, c, d), x in zip(rows, q.tolist(), strict=True)))
    return path


def test_observe_keeps_the_links_files_quality_as_resolve_does(tmp_path):
    links_csv = _links_file(tmp_path, quality=True)
    assert main(["resolve", "--links", str(links_csv), "--resolution", "evidence",
                 "--out", str(tmp_path / "resolved.csv")]) == 0
    want = (tmp_path / "resolved.csv").read_text().splitlines()
    assert want[0].endswith(",quality")
    got = _observe(tmp_path, links_csv, 3)
    assert got[0] == want[0]
    assert sorted(got[1:]) == sorted(want[1:])  # the same decisions and the same qualities
    assert any(",deleted," in r for r in got[1:])
