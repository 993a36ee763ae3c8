"""The memory guard's estimate of the evidence rule's detection (set lists of at most B + 1 ids
a feature) against hand counts."""

import pytest

from pipeline.budget import (
    BYTES_PER_LIST_ENTRY,
    BYTES_PER_SYNC_LINK,
    MemoryBudget,
    check_detection_memory,
    detection_entries,
)
from pipeline.errors import InputError
from pipeline.types import Links

# a chain of 5 features over 5 cameras (one set of 5) and one link (a set of 2)
LINKS = Links([0, 1, 2, 3, 0], [0, 0, 0, 0, 1], [1, 2, 3, 4, 1], [0, 0, 0, 0, 1])
FPC = [2, 2, 1, 1, 1]


def test_entries_of_the_rows_and_of_lists_of_at_most_keep_ids():
    assert detection_entries(FPC, LINKS) == (5 * 5 + 2 * 2, 5)
    assert detection_entries(FPC, LINKS, 3) == (5 * 3 + 2 * 2, 5)
    assert detection_entries(FPC, LINKS, 100) == detection_entries(FPC, LINKS)


def test_the_lists_are_counted_beside_the_links_and_refused_past_the_limit():
    need = len(LINKS) * BYTES_PER_SYNC_LINK + (5 * 3 + 2 * 2) * BYTES_PER_LIST_ENTRY
    budget = MemoryBudget(need / 1e9)
    check_detection_memory(FPC, LINKS, budget, detection=False, set_lists=2)
    assert budget.total == need
    with pytest.raises(InputError, match="evidence rule's detection.*5 features"):
        check_detection_memory(FPC, LINKS, (need - 1) / 1e9, detection=False, set_lists=2)


def test_the_fusion_stage_is_counted_per_track_robot_and_observer_pair():
    from pipeline.budget import (
        BYTES_PER_FUSION_OBSERVER_PAIR,
        BYTES_PER_FUSION_TRACK_ROBOT,
        check_fusion_memory,
        fusion_bytes,
    )

    # tracks 7 (3 observers), 9 (2) and 4 (1); -1 outside tracks
    labels = [7, 7, -1, 9, 7, 9, 4]
    need = 3 * 10 * BYTES_PER_FUSION_TRACK_ROBOT + (9 + 4 + 1) * BYTES_PER_FUSION_OBSERVER_PAIR
    assert fusion_bytes(10, [3, 2, 1]) == need
    check_fusion_memory(10, labels, need / 1e9)
    with pytest.raises(InputError, match=r"the fusion stage \(3 tracks among 10 robots, up to "
                                         r"3 observers a track\).*--no-fusion.*--max-memory-gb"):
        check_fusion_memory(10, labels, 0.999 * need / 1e9)


def test_a_formation_whose_fusion_exceeds_the_limit_is_refused_before_it_runs(tmp_path,
                                                                              monkeypatch):
    # the guard counts the fusion stage once the consistency stage has named the tracks: a
    # limit above everything before it but below the fusion's estimate stops the run there
    import pipeline.fusion.landmarks as landmarks
    from pipeline.runs.formation import FormationConfig, run_formation

    def never(*a, **k):
        raise AssertionError("the fusion stage ran")

    monkeypatch.setattr(landmarks, "fuse_tracks", never)
    config = FormationConfig(formation="d", size=(160, 120), max_features=300, rerun=False,
                             out=str(tmp_path / "run"), max_memory_gb=1e-4)
    with pytest.raises(InputError, match=r"the fusion stage \(\d+ tracks among 6 robots.*"
                                         r"--no-fusion"):
        run_formation(config)
    assert not (tmp_path / "run" / "links.csv").exists()


def test_an_online_run_counts_every_frame_it_renders_and_one_step_of_work():
    from pipeline.budget import BYTES_PER_FRAME_PIXEL, BYTES_PER_ROBOT_PIXEL, check_motion_memory

    need = 6 * 10 * 40 * 30 * BYTES_PER_FRAME_PIXEL + 6 * 40 * 30 * BYTES_PER_ROBOT_PIXEL
    check_motion_memory(6, 10, (40, 30), need / 1e9)  # exactly at the limit: accepted
    with pytest.raises(InputError, match=r"one step of 6 robots .* counted before it"):
        check_motion_memory(6, 11, (40, 30), need / 1e9)  # one more step's frames
    with pytest.raises(InputError, match=r"rendering 100 steps of 6 robots at 40x30 \(600 frames\)"
                       r".*fewer --steps"):
        check_motion_memory(6, 100, (40, 30), need / 1e9)


def test_rows_crossing_every_link_of_their_feature_are_counted_on_a_dense_set():
    """Alg. 1's detection sends each row (``|s|`` ids) over every link of its feature: on a
    set whose features all link to each other (a complete graph of 10 cameras), those
    crossings (10 · 2 · 45 = 900 entries), not the 100 entries held, bound the memory; the
    guard counted the held entries only, and ``resolve --resolution paper`` on the CMU
    hotel's 101 frames needed 7.5 GB where it estimated 0.25."""
    from itertools import combinations

    from pipeline.budget import BYTES_PER_ENTRY, BYTES_PER_ROW_CROSSING, row_crossings

    assert row_crossings(FPC, LINKS) == 2 * 4 * 5 + 2 * 1 * 2
    pairs = list(combinations(range(10), 2))
    dense = Links([i for i, _ in pairs], [0] * 45, [j for _, j in pairs], [0] * 45)
    fpc = [1] * 10
    assert detection_entries(fpc, dense) == (100, 10)
    assert row_crossings(fpc, dense) == 900
    need = 900 * BYTES_PER_ROW_CROSSING
    assert need > 100 * BYTES_PER_ENTRY
    budget = MemoryBudget(need / 1e9)
    check_detection_memory(fpc, dense, budget)
    assert budget.total == need
    with pytest.raises(InputError, match="sends each row over every link of its feature"):
        check_detection_memory(fpc, dense, (need - 1) / 1e9)


def test_the_batched_detection_counts_the_entries_it_holds_not_rows_in_flight():
    """Where the simulator's batched engine runs the detection (a lossless network, no
    fault) it forms each round's product of eq. (5) as one sparse product and holds no row
    in flight: the crossings are not counted there, and ``resolve --resolution paper`` on
    the CMU hotel's 101 frames (0.46 GB at the peak) is no longer refused at 8.3 GB."""
    from itertools import combinations

    from pipeline.budget import BYTES_PER_ENTRY

    pairs = list(combinations(range(10), 2))
    dense = Links([i for i, _ in pairs], [0] * 45, [j for _, j in pairs], [0] * 45)
    fpc = [1] * 10
    budget = MemoryBudget(100 * BYTES_PER_ENTRY / 1e9)
    check_detection_memory(fpc, dense, budget, in_flight=False)
    assert budget.total == 100 * BYTES_PER_ENTRY
    with pytest.raises(InputError, match="sends each row over every link of its feature"):
        check_detection_memory(fpc, dense, 100 * BYTES_PER_ENTRY / 1e9)  # in flight


def test_resolve_counts_rows_in_flight_only_off_the_batched_engine(tmp_path):
    """``resolve`` passes the engine it will run to the guard: on the simulator without
    faults the entries alone, over Zenoh the rows in flight too."""
    from unittest.mock import patch

    from pipeline.runs.resolve import resolve_file

    src = tmp_path / "links.csv"
    src.write_text("cam_i,feat_i,cam_j,feat_j\n0,0,1,0\n1,0,2,0\n0,0,2,0\n")
    seen = []
    with patch("pipeline.budget.check_detection_memory",
               side_effect=lambda *a, **kw: seen.append(kw.get("in_flight"))):
        resolve_file(src, tmp_path / "out.csv", resolution="paper")
    assert seen == [False]


def test_run_landmarks_counts_rows_in_flight_only_off_the_batched_engine():
    """``run-landmarks --resolution paper`` on the CMU hotel's 101 frames was refused at an
    estimated 9.9 GB of rows in flight on the simulator, whose batched detection holds none:
    its guard now counts them over Zenoh only."""
    from itertools import combinations

    from pipeline.budget import BYTES_PER_ENTRY, BYTES_PER_ROW
    from pipeline.runs.landmarks import LandmarksConfig, _check_memory

    pairs = list(combinations(range(10), 2))
    dense = Links([i for i, _ in pairs], [0] * 45, [j for _, j in pairs], [0] * 45)
    limit = (45 * BYTES_PER_ROW + 100 * BYTES_PER_ENTRY) / 1e9
    config = LandmarksConfig("unused", resolution="paper", baselines=False, max_memory_gb=limit)
    _check_memory([1] * 10, dense, config)
    config.transport = "zenoh"
    with pytest.raises(InputError, match="sends each row over every link of its feature"):
        _check_memory([1] * 10, dense, config)
