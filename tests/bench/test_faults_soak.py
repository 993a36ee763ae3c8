"""bench/faults.py: a count of formations it cannot run is refused before any work, and the
previous results.json stays as it was (it was replaced by a table of nothing)."""

import pytest
from benchload import load_bench


@pytest.mark.parametrize("count", ["0", "-2"])
def test_no_formation_is_refused_and_the_previous_results_stay(tmp_path, capsys, count):
    bench = load_bench("faults")
    bench.OUT = tmp_path
    (tmp_path / "results.json").write_text('{"previous": true}')
    with pytest.raises(SystemExit) as exc:
        bench.main(["--formations", count])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert f"argument --formations: '{count}': expected a whole number of at least 1" in err
    assert "Traceback" not in err
    assert (tmp_path / "results.json").read_text() == '{"previous": true}'
