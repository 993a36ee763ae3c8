"""Tests of viz.rerun_log: write a recording from a hand-built RunRecord and read it back."""

from __future__ import annotations

import uuid

import numpy as np
import pytest
import rerun as rr
from rerun.chunk import RrdReader

from pipeline.types import Features, LinkLedger, Links, RunRecord, View
from viz.recording_reader import count_strips, entity_paths
from viz.rerun_log import (
    CUT_COLORS,
    KEYPOINT_CLASSES,
    LINK_COLORS,
    PAIR_KEPT_SAMPLE,
    camera_entity,
    cut_summary,
    jpeg_bytes,
    keypoint_annotation_context,
    keypoint_status,
    link_endpoints_3d,
    log_run,
    replay_steps,
    world_axes_from_cameras,
)

W, H = 320, 240
K = np.array([[300.0, 0.0, (W - 1) / 2], [0.0, 300.0, (H - 1) / 2], [0.0, 0.0, 1.0]])


def look_at(centre: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """cam_from_world (R, t) of a camera at ``centre`` looking at the origin, world z up."""
    z = -centre / np.linalg.norm(centre)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    return R, -R @ centre


def project(R, t, X):
    x = (R @ X.T).T + t
    uv = (K @ x.T).T
    return uv[:, :2] / uv[:, 2:3]


# Links of the hand-built record: (cam_i, feat_i, cam_j, feat_j, status, reason, iteration, round,
# conflictive_before). Features 10..13 form two conflictive sets, each holding two features of
# camera 0 (Def. 2.4); resolution cuts one link of each; fusion cuts one more, non-conflictive.
LINKS = [
    *[(i, r, j, r, "kept", "", -1, -1, False) for i, j in ((0, 1), (0, 2), (1, 2))
      for r in range(6) if not (i == 1 and r == 5)],
    (1, 5, 2, 5, "deleted", "fusion-outlier", -1, 0, False),
    (0, 10, 1, 10, "kept", "", -1, -1, True),
    (1, 10, 2, 10, "kept", "", -1, -1, True),
    (0, 11, 2, 10, "deleted", "resolution", 0, 2, True),
    (0, 12, 1, 12, "deleted", "resolution", 0, 1, True),
    (1, 12, 2, 12, "kept", "", -1, -1, True),
    (0, 13, 2, 12, "kept", "", -1, -1, True),
]
N_DELETED = sum(row[4] == "deleted" for row in LINKS)


def make_record(posed: bool = True, n_cams: int = 3, size=(W, H)) -> RunRecord:
    rng = np.random.default_rng(0)
    X = rng.uniform(-1, 1, size=(16, 3))
    views, feats = [], []
    for i in range(n_cams):
        angle = 2 * np.pi * i / n_cams
        R, t = look_at(np.array([5 * np.cos(angle), 5 * np.sin(angle), 1.0]))
        image = rng.integers(0, 255, size=(size[1], size[0], 3), dtype=np.uint8)
        kp = project(R, t, X).astype(np.float32)
        views.append(View(name=f"cam{i:02d}", image=image, K=K.copy(),
                          R=R if posed else None, t=t if posed else None))
        feats.append(Features(kp, np.zeros((len(kp), 128), np.float32),
                              np.ones(len(kp), np.float32), "sift"))
    rows = [r for r in LINKS if r[0] < n_cams and r[2] < n_cams]
    col = list(zip(*rows, strict=True))
    links = Links(col[0], col[1], col[2], col[3])
    L = len(links)
    ledger = LinkLedger(links, status=np.array(col[4]), reason=np.array(col[5]),
                        iteration=np.array(col[6]), round=np.array(col[7]),
                        case=np.full(L, ""), truth=np.ones(L, np.int8),
                        conflictive_before=np.array(col[8]))
    return RunRecord(
        views=views, features=feats, ledger=ledger,
        points=X[:6], point_tracks=np.arange(6), gt_points=X[:6] + 0.01,
        fused_points=None, report_markdown="| metric | value |\n|---|---|\n| deleted | 3 |",
    )


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    record = make_record()
    record.fused_points = record.points[:4] - 0.01
    path = log_run(tmp_path_factory.mktemp("viz") / "recording.rrd", record,
                   recording_name="test", image_plane_distance=0.5)
    return path, record


def rgb24(rgb) -> int:
    """Rerun packs colours as 0xRRGGBBAA; ``packed >> 8`` drops the alpha."""
    return (rgb[0] << 16) | (rgb[1] << 8) | rgb[2]


def _chunks(path, entity, static=None):
    stream = RrdReader(path).store().stream().filter(content=entity)
    return [c for c in stream.to_chunks() if c.entity_path == entity
            and (static is None or c.is_static == static)]


def test_entities_present(recording):
    path, _ = recording
    paths = set(entity_paths(path))
    for cam in range(3):
        e = "/" + camera_entity(cam, name=f"cam{cam:02d}")
        assert {e, e + "/image", e + "/image/keypoints"} <= paths
    assert {"/world", "/world/links/kept", "/world/links/deleted", "/world/links/replay",
            "/world/points/triangulated", "/world/points/ground_truth", "/graph",
            "/world/points/fused", "/report", "/resolution/log"} <= paths


def test_one_strip_per_link(recording):
    path, record = recording
    assert count_strips(path, "world/links/deleted") == N_DELETED == 3
    assert count_strips(path, "world/links/kept") == len(record.ledger.links) - N_DELETED
    assert count_strips(path, "/world/links/replay") == len(record.ledger.links)
    assert count_strips(path, "world/links/absent") == 0


def blueprint_views(path) -> set[tuple[str, str]]:
    """``(view class, origin)`` of every view in the recording's default blueprint."""
    return {(kind, origin.lstrip("/")) for kind, origin, _ in blueprint_layout(path)[0].values()}


#: ``ContainerBlueprint:container_kind`` values
CONTAINER_KINDS = {1: "Tabs", 2: "Horizontal", 3: "Vertical", 4: "Grid"}


def blueprint_layout(path) -> tuple[dict, dict, dict, str]:
    """The default blueprint as saved: ``views`` {path: (class, origin, name)}, ``containers``
    {path: (kind, [child paths])}, ``hidden`` {view path: {entities hidden in it}} and the
    root container's path."""
    reader = RrdReader(path)
    (entry,) = reader.blueprints()
    views, containers, hidden, root = {}, {}, {}, None
    for chunk in reader.store(store=entry).stream().to_chunks():
        batch = chunk.to_record_batch()
        cols = batch.schema.names
        entity = str(chunk.entity_path)

        def last(name, batch=batch):
            return batch.column(name).to_pylist()[-1]

        if "ViewBlueprint:class_identifier" in cols:
            views[entity] = (last("ViewBlueprint:class_identifier")[0],
                             "/" + last("ViewBlueprint:space_origin")[0].lstrip("/"),
                             last("ViewBlueprint:display_name")[0])
        if "ContainerBlueprint:container_kind" in cols:
            containers[entity] = (CONTAINER_KINDS[last("ContainerBlueprint:container_kind")[0]],
                                  ["/" + c for c in last("ContainerBlueprint:contents")])
        if "EntityBehavior:visible" in cols and last("EntityBehavior:visible") == [False]:
            view, _, rest = entity.partition("/ViewContents/overrides/")
            hidden.setdefault(view, set()).add("/" + rest.removesuffix("/visualizers"))
        if "ViewportBlueprint:root_container" in cols:
            root = "/container/" + str(uuid.UUID(bytes=bytes(
                last("ViewportBlueprint:root_container")[0])))
    return views, containers, hidden, root


def test_the_first_views_show_what_was_cut_and_why(recording):
    path, record = recording
    views, containers, hidden, root = blueprint_layout(path)
    assert containers[root][0] == "Horizontal"
    main, side = containers[root][1]
    assert (containers[main][0], containers[side][0]) == ("Tabs", "Vertical")
    # the main area opens on the cut links, kept links (and the comparison points) hidden
    first = containers[main][1][0]
    assert views[first][:2] == ("3D", "/world") and views[first][2].startswith("Cut links")
    assert hidden[first] == {"/world/links/kept", "/world/points/ground_truth",
                             "/world/points/fused"}
    assert [views[v][2].split(":")[0] for v in containers[main][1][1:]] == [
        "All links", "Resolution replay (round timeline)"]
    # beside it, why: the cut summary, then the conflictive sets
    side_first, side_tabs = containers[side][1][:2]
    assert views[side_first][:2] == ("TextDocument", "/cuts")
    assert views[containers[side_tabs][1][0]][:2] == ("Graph", "/graph")
    (chunk,) = _chunks(path, "/cuts", static=True)
    assert chunk.to_record_batch().to_pydict()["TextDocument:text"][0][0] == cut_summary(record)


def test_cut_summary_says_when_there_was_no_conflictive_set():
    """With no conflictive set no graph is logged: the panel says so instead of describing
    a graph of sets."""
    record = make_record()
    assert "The graph shows each conflictive set" in cut_summary(record)
    record.ledger.conflictive_before[:] = False
    text = cut_summary(record)
    assert "The graph shows each conflictive set" not in text
    assert "There was no conflictive set before the resolution, so the graph is empty" in text


def test_cut_summary_counts_each_stage_and_says_why():
    record = make_record()
    text = cut_summary(record)
    deleted = record.ledger.status == "deleted"
    assert f"**{deleted.sum()} of {len(deleted)} links cut**" in text
    assert "* **2 links cut by resolution** (drawn red): it lay in a conflictive set" in text
    assert "* **1 link cut by fusion-outlier** (drawn purple): the robust fusion" in text
    record.ledger.case[deleted & (record.ledger.reason == "resolution")] = "evidence"
    assert "(evidence rule: the least-supported links of the set: 2)" in cut_summary(record)
    # every registered rule's cuts are named: sync's, and a rule registered later by its title
    record.ledger.case[deleted & (record.ledger.reason == "resolution")] = "sync"
    assert "(multi-way matching: the link would have joined" in cut_summary(record)
    from pipeline.consistency.rules import ResolutionRule, register, unregister

    register(ResolutionRule(name="toy-why", help="", title="a toy rule", summary="",
                            cases={99: "toy-why"}, detection=False, stage="x:y", alone="x:y"))
    try:
        record.ledger.case[deleted & (record.ledger.reason == "resolution")] = "toy-why"
        assert "(toy-why rule: a toy rule: 2)" in cut_summary(record)
    finally:
        unregister("toy-why")


def test_blueprint_saved(recording):
    path, _ = recording
    assert len(RrdReader(path).recordings()) == 1
    views = blueprint_views(path)
    assert {("3D", "world"), ("2D", "world/cam00/image"), ("Graph", "graph"),
            ("TextDocument", "report")} <= views


def test_camera_pose_is_child_from_parent(recording):
    path, record = recording
    (chunk,) = _chunks(path, "/world/cam01", static=True)
    batch = chunk.to_record_batch().to_pydict()
    np.testing.assert_allclose(batch["Transform3D:translation"][0][0], record.views[1].t, rtol=1e-6)
    # Rerun stores Mat3x3 column-major.
    mat = np.array(batch["Transform3D:mat3x3"][0][0]).reshape(3, 3).T
    np.testing.assert_allclose(mat, record.views[1].R, atol=1e-6)
    relation = batch["Transform3D:relation"][0][0]
    assert relation == rr.TransformRelation.ChildFromParent.value


def test_strip_endpoints_lie_on_keypoint_rays():
    record = make_record()
    depth = 0.7
    ends = link_endpoints_3d(record, depth)
    assert ends.shape == (len(record.ledger.links), 2, 3)
    lk = record.ledger.links
    for side, (cam, feat) in enumerate(((lk.cam_i, lk.feat_i), (lk.cam_j, lk.feat_j))):
        for k in range(len(lk)):
            v = record.views[cam[k]]
            x = v.R @ ends[k, side] + v.t
            assert x[2] == pytest.approx(depth, rel=1e-5)
            uv = (K @ x)[:2] / x[2]
            np.testing.assert_allclose(uv, record.features[cam[k]].keypoints[feat[k]], atol=1e-3)


def test_stored_strips_match_geometry(recording):
    path, record = recording
    (chunk,) = _chunks(path, "/world/links/deleted", static=True)
    d = chunk.to_record_batch().to_pydict()
    strips = np.array(d["LineStrips3D:strips"][-1])
    assert d["LineStrips3D:labels"][-1][0] == "1:5–2:5 (good) cut by fusion-outlier"
    deleted = record.ledger.status == "deleted"
    np.testing.assert_allclose(strips, link_endpoints_3d(record, 0.5)[deleted], atol=1e-5)


def test_replay_follows_the_order_the_run_cut_links():
    """A robot declared lost in iteration 1 cuts its links before the resolution of
    iteration 2, and both before the fusion; the checks before the consistency stage
    (clean-db) come first, whatever the names of the stages."""
    record = make_record()
    ledger = record.ledger
    status = np.array(ledger.status, dtype=object)
    reason = np.array(ledger.reason, dtype=object)
    iteration = np.array(ledger.iteration, dtype=np.int64)
    rnd = np.array(ledger.round, dtype=np.int64)
    res = np.flatnonzero(reason == "resolution")
    iteration[res], rnd[res] = 2, [1, 2]
    kept = np.flatnonzero(status == "kept")
    status[kept[:3]] = "deleted"
    reason[kept[:3]] = ["robot-lost", "not-comm-edge", "robot-lost"]
    iteration[kept[:3]], rnd[kept[:3]] = [1, -1, 2], [40, -1, 1]
    record.ledger = LinkLedger(ledger.links, status=status.astype(str),
                               reason=reason.astype(str), iteration=iteration, round=rnd,
                               case=ledger.case, truth=ledger.truth,
                               conflictive_before=ledger.conflictive_before)
    step, keys = replay_steps(record)
    assert keys == [("not-comm-edge", -1, -1), ("robot-lost", 1, 40), ("resolution", 2, 1),
                    ("robot-lost", 2, 1), ("resolution", 2, 2), ("fusion-outlier", -1, 0)]
    for k, (stage, i, r) in enumerate(keys, start=1):
        at = (record.ledger.reason == stage) & (record.ledger.iteration == i) \
            & (record.ledger.round == r) & (record.ledger.status == "deleted")
        assert at.any() and (step[at] == k).all()
    assert (step[record.ledger.status == "kept"] == len(keys) + 1).all()


def test_replay_order_and_final_colours(recording):
    path, record = recording
    step, keys = replay_steps(record)
    # Resolution before fusion; within resolution by (iteration, round).
    assert keys == [("resolution", 0, 1), ("resolution", 0, 2), ("fusion-outlier", -1, 0)]
    deleted = record.ledger.status == "deleted"
    assert (step[~deleted] == len(keys) + 1).all()
    assert step[(record.ledger.reason == "resolution") & (record.ledger.round == 1)].tolist() == [1]

    rows = {}
    for chunk in _chunks(path, "/world/links/replay", static=False):
        d = chunk.to_record_batch().to_pydict()
        for s, colors in zip(d["round"], d["LineStrips3D:colors"], strict=True):
            rows[int(s)] = np.array(colors, dtype=np.uint32) >> 8
    assert sorted(rows) == list(range(len(keys) + 2))

    assert (rows[0] == rgb24(LINK_COLORS["candidate"])).all()
    final = rows[len(keys) + 1]
    # resolution cuts red, fusion cuts purple: the two stages are told apart
    by_res = deleted & (record.ledger.reason == "resolution")
    assert (final[by_res] == rgb24(CUT_COLORS["resolution"])).all()
    assert (final[deleted & ~by_res] == rgb24(CUT_COLORS["fusion-outlier"])).all()
    assert CUT_COLORS["resolution"] != CUT_COLORS["fusion-outlier"]
    assert (final[~deleted] == rgb24(LINK_COLORS["kept"])).all()
    # After step 1 only the link cut in resolution round 1 is red.
    assert (rows[1] == rgb24(LINK_COLORS["cut"])).sum() == 1


def test_graph_shows_conflictive_sets_and_cuts(recording):
    path, record = recording
    (static,) = _chunks(path, "/graph", static=True)
    d = static.to_record_batch().to_pydict()
    nodes, edges = d["GraphNodes:node_ids"][0], d["GraphEdges:edges"][0]
    conf = record.ledger.conflictive_before
    cut = conf & (record.ledger.status == "deleted")
    assert {"0:10", "0:11", "2:10", "0:12", "0:13", "1:12"} <= set(nodes)
    markers = [n for n in nodes if n.startswith("cut:")]
    assert sorted(markers) == sorted(f"cut:{k}" for k in np.flatnonzero(cut))
    assert len(edges) == conf.sum() + cut.sum() == 8  # a cut link is drawn through its marker

    colors = {}
    for chunk in _chunks(path, "/graph", static=False):
        t = chunk.to_record_batch().to_pydict()
        for s, c in zip(t["round"], t["GraphNodes:colors"], strict=True):
            colors[int(s)] = np.array(c[len(nodes) - len(markers):], dtype=np.uint32) >> 8
    red = rgb24(LINK_COLORS["cut"])
    assert (colors[0] != red).all()           # before resolution: every marker a candidate
    assert (colors[1] == red).sum() == 1      # resolution round 1 cut one conflictive link
    assert (colors[max(colors)] == red).all()


def test_keypoint_status_hand_computed():
    record = make_record()
    status = keypoint_status(record)
    m = len(record.features[0])
    cam0 = status[:m]
    assert cam0[0] == 1            # kept, not conflictive
    assert cam0[10] == 2           # conflictive, its links kept
    assert cam0[11] == 3           # endpoint of a link cut by resolution
    assert cam0[12] == 3
    assert cam0[14] == 0           # never linked
    assert status[m + 5] == 4      # camera 1 feature 5: cut by fusion


def test_keypoints_logged_with_status_classes(recording):
    path, record = recording
    (chunk,) = _chunks(path, "/world/cam00/image/keypoints", static=True)
    d = chunk.to_record_batch().to_pydict()
    np.testing.assert_array_equal(d["Points2D:class_ids"][0],
                                  keypoint_status(record)[:len(record.features[0])])
    # Rerun puts the top-left pixel's centre at (0.5, 0.5), OpenCV at (0, 0).
    np.testing.assert_allclose(d["Points2D:positions"][0],
                               record.features[0].keypoints + 0.5, atol=1e-4)


def test_annotation_context_equals_rerun_own_conversion():
    ours = keypoint_annotation_context().context.as_arrow_array()
    theirs = rr.AnnotationContext([(k, label, rgb) for k, (label, rgb)
                                   in KEYPOINT_CLASSES.items()]).context.as_arrow_array()
    assert ours.type == theirs.type and ours.equals(theirs)


def test_annotation_context_logged_at_the_root(recording):
    path, _ = recording
    (chunk,) = _chunks(path, "/", static=True)
    (context,) = chunk.to_record_batch().to_pydict()["AnnotationContext:context"]
    got = {c["class_id"]: (c["class_description"]["info"]["label"],
                           c["class_description"]["info"]["color"]) for c in context[0]}
    assert got == {k: (label, (r << 24) | (g << 16) | (b << 8) | 0xFF)
                   for k, (label, (r, g, b)) in KEYPOINT_CLASSES.items()}


def test_real_images_without_poses(tmp_path):
    record = make_record(posed=False)
    for v in record.views:  # gray images, as a folder of real photos may hold
        v.image = np.ascontiguousarray(v.image[..., 0])
    record.points, record.point_tracks, record.gt_points = np.zeros((0, 3)), np.zeros(0), None
    path = log_run(tmp_path / "real.rrd", record)
    paths = set(entity_paths(path))
    assert {"/images/cam00/image", "/images/cam02/image/keypoints", "/graph", "/report"} <= paths
    assert not any(p.startswith("/world/links") or p.startswith("/world/cam") for p in paths)
    assert count_strips(path, "world/links/deleted") == 0
    views = blueprint_views(path)
    assert ("2D", "images/cam00/image") in views and ("Graph", "graph") in views
    assert not any(kind == "3D" for kind, _ in views)  # no poses and no points: nothing 3D


def test_camera_without_pose_among_posed_ones(tmp_path):
    """A camera the mapper did not register: its links leave world/links, the rest stay."""
    record = make_record()
    record.views[2].R = record.views[2].t = None
    path = log_run(tmp_path / "mixed.rrd", record)
    paths = set(entity_paths(path))
    assert {"/world/cam00", "/images/cam02/image", "/graph"} <= paths
    assert "/world/cam02" not in paths
    both_posed = (record.ledger.links.cam_j < 2)
    deleted = record.ledger.status == "deleted"
    assert count_strips(path, "world/links/deleted") == (deleted & both_posed).sum() == 1
    assert count_strips(path, "world/links/kept") == (~deleted & both_posed).sum()
    ends = link_endpoints_3d(record, 1.0)
    assert np.isnan(ends[~both_posed, 1]).all() and np.isfinite(ends[~both_posed, 0]).all()


def test_no_links_and_a_camera_without_features(tmp_path):
    record = make_record()
    z = np.zeros(0, np.int64)
    record.ledger = LinkLedger(Links(z, z, z, z), np.zeros(0, str), np.zeros(0, str), z, z,
                               np.zeros(0, str), np.zeros(0, np.int8), np.zeros(0, bool))
    record.features[1] = Features(np.zeros((0, 2), np.float32), np.zeros((0, 128), np.float32),
                                  np.zeros(0, np.float32), "sift")
    path = log_run(tmp_path / "empty.rrd", record)
    assert count_strips(path, "world/links/kept") == count_strips(path, "world/links/deleted") == 0
    assert {"/world/links/kept", "/world/links/deleted", "/world/cam01/image"} <= set(
        entity_paths(path))
    assert "/graph" not in entity_paths(path)  # no conflictive sets
    assert "/world/points/fused" not in entity_paths(path)  # fused_points is None


def test_failed_write_leaves_no_file(tmp_path):
    record = make_record()
    record.ledger.status = record.ledger.status[:-1]
    with pytest.raises(ValueError, match="status"):
        log_run(tmp_path / "bad.rrd", record)
    assert list(tmp_path.iterdir()) == []


def test_six_vga_images_stay_small(tmp_path):
    """6 images of 640x480 (smooth texture with detail, like a rendered scene) under 2 MB."""
    record = make_record(n_cams=3, size=(640, 480))
    rng = np.random.default_rng(1)
    views, feats = [], []
    for k in range(6):
        v = record.views[k % 3]
        yy, xx = np.mgrid[0:480, 0:640]
        base = 128 + 60 * np.sin(xx / (9 + k)) * np.cos(yy / 13)
        img = np.clip(base[..., None] + rng.normal(0, 12, (480, 640, 3)), 0, 255).astype(np.uint8)
        views.append(View(f"cam{k:02d}", img, K, v.R, v.t))
        feats.append(record.features[k % 3])
    record.views, record.features = views, feats
    path = log_run(tmp_path / "six.rrd", record)
    assert path.stat().st_size < 2_000_000


def test_world_axes_follow_the_cameras_up_direction():
    record = make_record()
    assert world_axes_from_cameras(record.views) == rr.ViewCoordinates.RIGHT_HAND_Z_UP
    # The same cameras in a y-down frame (x_new = (x, -z, y)): a COLMAP-like model.
    flip = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])
    for v in record.views:
        v.R = v.R @ flip.T
    assert world_axes_from_cameras(record.views) == rr.ViewCoordinates.RIGHT_HAND_Y_DOWN
    for v in record.views:
        v.R = None
    assert world_axes_from_cameras(record.views) == rr.ViewCoordinates.RIGHT_HAND_Z_UP


def test_entities_named_after_the_images_and_a_pair_view(tmp_path, monkeypatch):
    from viz import rerun_log

    record = make_record()
    for k, v in enumerate(record.views):
        v.name = f"IMG {k}.jpg"  # a file name with a space
    record.point_colors = np.tile(np.array([[10, 200, 30]], np.uint8), (len(record.points), 1))
    monkeypatch.setattr(rerun_log, "PAIR_KEPT_SAMPLE", 1)  # of the pair's kept links, one
    path = log_run(tmp_path / "named.rrd", record, view_pairs=[(0, 2)])
    paths = set(entity_paths(path))
    assert "/" + camera_entity(0, True, "IMG 0.jpg") + "/image" in paths
    assert not any("cam_0" in p for p in paths)
    pair = "/matches/" + rr.escape_entity_path_part("IMG 0.jpg--IMG 2.jpg")
    assert {pair, pair + "/kept", pair + "/cut"} <= paths
    sel = ((record.ledger.links.cam_i == 0) & (record.ledger.links.cam_j == 2))
    deleted = record.ledger.status == "deleted"
    (chunk,) = _chunks(path, pair + "/cut", static=True)
    assert len(chunk.to_record_batch().to_pydict()["LineStrips2D:strips"][0]) == (sel & deleted).sum()
    (chunk,) = _chunks(path, pair + "/kept", static=True)
    assert (sel & ~deleted).sum() > 1
    assert len(chunk.to_record_batch().to_pydict()["LineStrips2D:strips"][0]) == 1
    views, _, _, _ = blueprint_layout(path)
    name = next(n for kind, origin, n in views.values() if origin == pair)
    assert name.endswith(f": {(sel & deleted).sum()} cut, 1 of {(sel & ~deleted).sum()} kept")
    assert PAIR_KEPT_SAMPLE == 25
    assert count_strips(path, "world/links/deleted") == deleted.sum()
    (chunk,) = _chunks(path, "/world/points/triangulated", static=True)
    colors = np.array(chunk.to_record_batch().to_pydict()["Points3D:colors"][0], np.uint32) >> 8
    assert (colors == rgb24((10, 200, 30))).all()


@pytest.mark.parametrize("shape", [(24, 32, 3), (24, 32)])
def test_jpeg_bytes_keep_colour_order_and_size(shape):
    """The recording's JPEGs decode (by Pillow, as any viewer would) to the logged image:
    same size, red stays red (OpenCV encodes BGR, the views are RGB)."""
    from io import BytesIO

    from PIL import Image

    image = np.zeros(shape, np.uint8)
    image[..., 0] = 200  # red in RGB; the whole image for a gray one
    data = jpeg_bytes(image, 90)
    decoded = np.asarray(Image.open(BytesIO(data)))
    assert decoded.shape == image.shape
    assert np.abs(decoded.astype(int) - image).max() <= 3


def test_jpeg_bytes_refuse_what_they_cannot_encode():
    assert jpeg_bytes(np.zeros((4, 4, 4), np.uint8), 85) is None  # RGBA
    assert jpeg_bytes(np.zeros((4, 4), np.float32), 85) is None


def test_replay_log_names_no_unknown_iteration_or_round(recording):
    """The fusion's cuts and a saved run's (whose links.csv holds no iteration) carry -1 for
    what is not known: the step's line leaves it out instead of saying 'iteration -1'."""
    path, _ = recording
    lines = [t for c in _chunks(path, "/resolution/log", static=False)
             for row in c.to_record_batch().to_pydict()["TextLog:text"] for t in row]
    assert "step 1: resolution, iteration 0, round 1: 1 link cut" in lines
    assert "step 3: fusion-outlier, round 0: 1 link cut" in lines
    assert not any("-1" in t for t in lines)
