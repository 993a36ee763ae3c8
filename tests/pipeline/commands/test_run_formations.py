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


def test_the_summary_title_names_every_option_that_changes_the_counts(tmp_path, monkeypatch):
    """formations.md's title named the seed, features, size and rule, not the keypoint merge
    radius nor the feature budget: a run at --merge-radius 2 (other counts than the README's
    0.5 px) carried the title of a default run."""
    monkeypatch.setenv("FORMATION_MATCH_CACHE", str(tmp_path / "cache"))
    out = tmp_path / "runs"
    for extra, title in (
            ([], "# Formations (a)–(d), seed 0, sift (2000 features per image), 64x48, "
                 "resolution paper, keypoint merge radius 0.5 px"),
            (["--merge-radius", "2", "--max-features", "300", "--resolution", "evidence"],
             "# Formations (a)–(d), seed 0, sift (300 features per image), 64x48, "
             "resolution evidence, keypoint merge radius 2 px")):
        assert main(["run-formations", "-q", "--size", "64x48", "--out", str(out), *extra]) == 0
        assert (out / "formations.md").read_text().splitlines()[0] == title
