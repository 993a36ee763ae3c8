"""bench/voting_fig23.py without matplotlib (the bench extra): one error line naming what to
install, exit status 2, nothing written (it was a ModuleNotFoundError traceback)."""

import importlib.util

import pytest
from benchload import load_bench


def test_without_matplotlib_it_says_what_to_install(tmp_path, capsys, monkeypatch):
    bench = load_bench("voting_fig23")
    find_spec = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "matplotlib" else find_spec(name, *a))
    monkeypatch.setitem(__import__("sys").modules, "matplotlib", None)  # import fails too
    with pytest.raises(SystemExit) as exc:
        bench.main(["--out", str(tmp_path / "out")])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "error: matplotlib is missing, for the figure fig2_3.png" in err
    assert "Traceback" not in err and not (tmp_path / "out").exists()
