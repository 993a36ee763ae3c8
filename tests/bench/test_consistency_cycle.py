"""bench/consistency_cycle.py records the machine's load at the start and at the end of its
runs (the README quotes both), prints them, and the printed figures are the saved ones."""

import json
import re

from benchload import load_bench


def test_the_load_at_the_start_and_the_end_is_printed_and_saved(tmp_path, capsys):
    assert load_bench("consistency_cycle").main(
        ["--n", "3", "--repeat", "1", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    saved = json.loads((tmp_path / "results.json").read_text())
    assert not (tmp_path / "meta.json").exists()  # one file, replaced at once
    meta = saved["meta"]
    start, end = meta["load_average_at_start"][0], meta["load_average"][0]
    assert re.search(rf"load average {start:.1f} at the start, {end:.1f} at the end", out)
    (paper, evidence) = saved["records"]
    assert re.search(rf"\n +3 +paper +{paper['wall_s']:.2f} +{paper['peak_rss_mb']:.1f} +0 ", out)
