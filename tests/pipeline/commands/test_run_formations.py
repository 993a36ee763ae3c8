"""run-formations prints each formation's warnings about its result on stderr, as
run-formation does (README, "Errors you can meet": even with --quiet)."""

import json

from pipeline.__main__ import main


def test_a_formation_without_links_is_warned_on_stderr(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("FORMATION_MATCH_CACHE", str(tmp_path / "cache"))
    out = tmp_path / "runs"
    # 64x48: too small for any pair of views to match (no link in any formation)
    assert main(["run-formations", "-q", "--size", "64x48", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    for name in "abcd":
        report = json.loads((out / f"formation-{name}" / "report.json").read_text())
        assert [w["code"] for w in report["warnings"]] == ["no-links"]
        assert (f"warning: formation {name}: {report['warnings'][0]['message']}"
                in err.splitlines())


def test_an_empty_out_is_refused_not_the_current_folder(tmp_path, monkeypatch, capsys):
    """--out "$UNSET" wrote formation-a..d, formations.md and formations.json into the current
    folder; it is refused as run-formation refuses it, before any work."""
    monkeypatch.chdir(tmp_path)
    assert main(["run-formations", "-q", "--size", "64x48", "--out", ""]) == 2
    assert capsys.readouterr().err == ("error: --out '' is empty (an unset variable?); give a "
                                       "folder name, e.g. runs\n")
    assert list(tmp_path.iterdir()) == []
