"""What README says the recording of ``python -m viz.saved_run`` leaves out is what it leaves
out."""

from pathlib import Path

from test_rerun_log import make_record
from test_saved_run import _save

from viz.recording_reader import entity_paths
from viz.saved_run import main

README = Path(__file__).resolve().parents[2] / "README.md"


def _saved_run_paragraph() -> str:
    text = README.read_text()
    start = text.index("`python -m viz.saved_run RUN_DIR` writes the recording")
    return " ".join(text[start:text.index("\n\n", start)].split())


def test_readme_does_not_say_the_conflict_graph_is_left_out(tmp_path):
    """README said the saved recording has 'no conflict graph'; it has one, recomputed from
    links.csv (every link matching produced), as the run computed it."""
    folder = _save(make_record(), tmp_path / "run")
    assert main([str(folder)]) == 0
    assert "/graph" in entity_paths(folder / "recording.rrd")
    said = _saved_run_paragraph()
    assert "no conflict graph" not in said, said
    assert "conflict graph is recomputed from `links.csv`" in said, said
