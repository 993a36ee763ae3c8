"""The benches' time and memory caps (multiway --cap-gb and --cap-s, sync_scaling --timeout)
are finite numbers above 0, checked when parsed: 0 or a negative cap failed every method or
case (each saved as 'out of memory (cap 0 GB)' or 'over 0 s' over the previous results), nan
failed every method of multiway on 'cannot convert float NaN to integer' or lifted
sync_scaling's timeout; and a cap under one second is kept, where multiway's int() of it set
no alarm at all."""

import time

import pytest
from benchload import load_bench, previous_results, refused

TEAM_ONLY = ["--frames", "--graffiti", "", "--formations", "", "--warped-seeds", "--team", "4"]


@pytest.mark.parametrize("name, args", [
    ("multiway", [*TEAM_ONLY, "--cap-gb", "0"]),
    ("multiway", [*TEAM_ONLY, "--cap-gb", "nan"]),
    ("multiway", [*TEAM_ONLY, "--cap-s", "-1"]),
    ("multiway", [*TEAM_ONLY, "--cap-s", "nan"]),
    ("sync_scaling", ["--cases", "ring2:8", "--timeout", "0"]),
    ("sync_scaling", ["--cases", "ring2:8", "--timeout", "nan"]),
])
def test_a_cap_no_run_can_meet_is_refused_when_parsed(tmp_path, capsys, name, args):
    out = previous_results(tmp_path)
    err = refused(load_bench(name).main, [*args, "--out", str(out)], out, capsys)
    assert f"argument {args[-2]}: {args[-1]!r}: expected a finite number above 0" in err


def test_a_cap_under_a_second_stops_the_method(monkeypatch):
    multiway = load_bench("multiway")

    def slow(method, case, cap_gb):
        time.sleep(3)
        raise AssertionError("not stopped")
    monkeypatch.setattr(multiway, "run_method", slow)
    t0 = time.perf_counter()
    got = multiway.measured("sync", None, 6.0, 0.5)
    assert got == {"status": "timed out after 0.5 s"}
    assert time.perf_counter() - t0 < 2.5
