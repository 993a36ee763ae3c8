"""multiway and sync_weights check that --data holds the labelled images their cases take
before the first case: on a folder of 6 images the warped copies (30 images each) were refused
as '--frames 30: expected 2..6', a value no one gave, after every labelled case had run, and a
--frames count above the folder's after the counts before it."""

from pathlib import Path

import pytest
from benchload import load_bench

ROOT = Path(__file__).resolve().parents[2]
HOTEL = ROOT / "tests" / "data" / "cmu_hotel_small"
WARPED = (f"error: --warped-seeds: the warped copies take 30 labelled images of --data {HOTEL}, "
          "which holds 6; give a larger set, or --warped-seeds with no seed to skip them")


@pytest.mark.parametrize("name, args, message", [
    ("multiway", ["--frames", "4", "--warped-seeds", "1"], WARPED),
    ("multiway", ["--frames", "4", "8", "--warped-seeds"],
     f"error: --frames 8: expected 2..6 (--data {HOTEL} holds 6 labelled images)"),
    ("sync_weights", ["--frames", "4", "--warped-seeds", "1"], WARPED),
])
def test_a_data_folder_too_small_for_a_case_is_refused_before_the_first(tmp_path, capsys,
                                                                        monkeypatch, name, args,
                                                                        message):
    multiway = load_bench("multiway")
    bench = multiway if name == "multiway" else load_bench(name)

    def no_case(*a, **k):
        raise AssertionError("a case ran before the refusal")
    monkeypatch.setattr(bench, "multiway", multiway, raising=False)
    monkeypatch.setattr(multiway, "landmark_case", no_case)
    out = tmp_path / "bench"
    out.mkdir()
    (out / "results.json").write_text('{"previous": true}')
    extra = ["--graffiti", "", "--formations", ""] if name == "multiway" else []
    code = bench.main(["--data", str(HOTEL), *args, "--team", *extra, "--out", str(out)])
    assert code == 2
    assert capsys.readouterr().err.strip() == message
    assert (out / "results.json").read_text() == '{"previous": true}'
