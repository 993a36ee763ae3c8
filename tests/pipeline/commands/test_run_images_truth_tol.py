"""run-images --truth-tol takes a finite number of pixels above 0.

``--truth-tol inf`` ran: every link counted as good (on homographies of another size, whose
links agree with none of them, the report said 0 spurious links and nothing warned).
"""

import shutil
from pathlib import Path

import pytest

from pipeline.__main__ import main

GRAF_SMALL = Path(__file__).resolve().parents[2] / "data" / "graffiti_small"


@pytest.mark.parametrize("tol", ["inf", "-inf", "nan", "0", "-2"])
def test_a_tolerance_that_is_not_a_finite_positive_number_is_refused(tmp_path, capsys, tol):
    photos = tmp_path / "graffiti"
    shutil.copytree(GRAF_SMALL, photos)
    out = tmp_path / "run"
    assert main(["run-images", str(photos), "--truth", "homographies", f"--truth-tol={tol}",
                 "--no-rerun", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1 and "Traceback" not in err, err
    assert lines[0].startswith(f"error: --truth-tol {float(tol)}: expected a finite number "
                               "of pixels > 0"), lines[0]
    assert "[load]" not in err and not out.exists()
