"""run-landmarks on a folder that is a symbolic link to itself ended in a RuntimeError
traceback from Path.resolve() (naming the default run folder), as run-images did; it is now
refused naming the loop, and a link to a drive not mounted names its target."""

from pipeline.__main__ import main


def test_a_landmarks_folder_that_is_a_loop_of_links_is_named(tmp_path, capsys):
    (tmp_path / "loop").symlink_to("loop")
    assert main(["run-landmarks", str(tmp_path / "loop"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err == (f"error: {tmp_path / 'loop'} is a symbolic link that leads back to itself "
                   "(to 'loop', a loop of links); make it lead to a file or folder\n")


def test_a_landmarks_folder_linked_nowhere_names_its_target(tmp_path, capsys):
    (tmp_path / "hotel").symlink_to(tmp_path / "unmounted" / "hotel")
    assert main(["run-landmarks", str(tmp_path / "hotel"), "--quiet"]) == 2
    assert capsys.readouterr().err == (
        f"error: {tmp_path / 'hotel'} is a symbolic link that leads nowhere (to "
        f"{str(tmp_path / 'unmounted' / 'hotel')!r}); mount or create its target\n")
