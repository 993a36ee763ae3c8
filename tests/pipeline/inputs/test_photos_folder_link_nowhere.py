"""run-images on a photo folder that is a symbolic link to a drive not mounted (or reached
through one): the error said only that the folder does not exist, while the user sees it
listed; it now names the link and where it leads."""

import numpy as np
import pytest
from PIL import Image

from pipeline.errors import InputError
from pipeline.inputs.photos import load_folder
from pipeline.inputs.sequence import load_sequence


def test_a_folder_linked_nowhere_is_named_with_its_target(tmp_path):
    (tmp_path / "photos").symlink_to(tmp_path / "unmounted" / "photos")
    with pytest.raises(InputError) as err:
        load_folder(tmp_path / "photos")
    assert str(err.value) == (
        f"image folder {str(tmp_path / 'photos')!r} is a symbolic link that leads nowhere (to "
        f"{str(tmp_path / 'unmounted' / 'photos')!r}); mount or create its target")


def test_a_link_nowhere_on_the_way_is_named(tmp_path):
    (tmp_path / "drive").symlink_to(tmp_path / "unmounted")
    with pytest.raises(InputError) as err:
        load_folder(tmp_path / "drive" / "set1")
    assert str(err.value) == (
        f"image folder {str(tmp_path / 'drive' / 'set1')!r} does not exist: "
        f"{str(tmp_path / 'drive')!r} on its way is a symbolic link that leads nowhere (to "
        f"{str(tmp_path / 'unmounted')!r}); mount or create its target")


def test_a_sequence_folder_linked_nowhere_is_named_with_its_target(tmp_path):
    (tmp_path / "frames").symlink_to("/nonexistent-drive/frames")
    with pytest.raises(InputError, match=r"^--sequence '.*frames' is a symbolic link that leads "
                       r"nowhere \(to '/nonexistent-drive/frames'\)"):
        load_sequence(tmp_path / "frames")


def test_a_missing_folder_still_says_so(tmp_path):
    Image.fromarray(np.zeros((4, 4), np.uint8)).save(tmp_path / "a.png")
    with pytest.raises(InputError, match=r"^image folder '.*missing' does not exist$"):
        load_folder(tmp_path / "missing")


@pytest.mark.parametrize("sequence", [False, True], ids=["run-images", "--sequence"])
def test_a_photo_folder_that_is_a_loop_of_links_is_named(tmp_path, capsys, sequence):
    """A symbolic link leading to itself as DIR: Path.resolve() raised RuntimeError('Symlink
    loop') and the command ended in a traceback (exit 1), before any check named it."""
    from pipeline.__main__ import main

    (tmp_path / "loop").symlink_to("loop")
    argv = ["run-images", str(tmp_path / "loop"), "--no-rerun", "--quiet"] + (
        ["--sequence"] if sequence else [])
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and err.count("\n") == 1
    assert f"{str(tmp_path / 'loop')!r} is a symbolic link that leads back to itself (to " \
           "'loop', a loop of links); make it lead to a file or folder" in err


def test_a_database_that_is_a_loop_of_links_is_refused(tmp_path, capsys):
    from pipeline.__main__ import main

    (tmp_path / "in.db").symlink_to("in.db")
    assert main(["clean-db", str(tmp_path / "in.db"), "--out", str(tmp_path / "o.db")]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and err.startswith("error: database ")
