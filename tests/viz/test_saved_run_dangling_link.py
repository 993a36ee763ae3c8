"""``python -m viz.saved_run LINK`` where LINK is a symbolic link to a folder no longer there
(a drive not mounted) blamed the recording to write ('choose another place with --out');
the run folder is now named as the link leading nowhere, with or without --out."""

from viz.saved_run import main


def test_a_run_folder_link_leading_nowhere_is_named(tmp_path, capsys):
    link = tmp_path / "run"
    link.symlink_to(tmp_path / "unmounted" / "run")
    for extra in ([], ["--out", str(tmp_path / "r.rrd")]):
        assert main([str(link), *extra]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"error: {link} is a symbolic link that leads nowhere (to "), err
        assert "--out FILE.rrd" not in err and err.count("\n") == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]
