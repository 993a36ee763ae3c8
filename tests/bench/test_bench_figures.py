"""A bench that saves a figure beside its results (consistency_scale's time_bytes.png,
voting_fig23's fig2_3.png) replaces both together: a Ctrl-C while the figure was drawn left
the new results beside a half-written figure (consistency_scale) or a new figure beside the
previous results (voting_fig23)."""

import pytest
from benchload import load_bench

PREVIOUS = {"results.json": '{"previous": true}', "time_bytes.png": "previous figure",
            "fig2_3.json": '{"previous": true}', "fig2_3.png": "previous figure"}


def _interrupted_drawing(path):
    with open(path, "w") as f:
        f.write("half a figure")
    raise KeyboardInterrupt


@pytest.mark.parametrize("name, args, drawer, files", [
    ("consistency_scale", ["--n", "6", "--repeat", "1", "--resolution", "paper", "--features",
                           "40", "--per-robot-max-n", "0"], "plot",
     ("results.json", "time_bytes.png")),
    ("voting_fig23", [], "plot_fig23", ("fig2_3.json", "fig2_3.png")),
])
def test_a_ctrl_c_while_the_figure_is_drawn_keeps_the_previous_outputs(tmp_path, capsys,
                                                                       monkeypatch, name,
                                                                       args, drawer, files):
    pytest.importorskip("matplotlib")
    bench = load_bench(name)
    if drawer == "plot":
        monkeypatch.setattr(bench, drawer, lambda records, path: _interrupted_drawing(path))
    else:
        monkeypatch.setattr(bench, drawer, _interrupted_drawing)
    for f in files:
        (tmp_path / f).write_text(PREVIOUS[f])
    try:  # one_line_errors: one line, exit status 130
        code = bench.main([*args, "--out", str(tmp_path)])
    except SystemExit as exc:
        code = exc.code
    assert code == 130
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(files)
    for f in files:
        assert (tmp_path / f).read_text() == PREVIOUS[f]
