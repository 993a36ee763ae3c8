"""run-images --sequence on a flat folder of photographs (no robot sub-folders): the error
says where the images are and that the run without --sequence reads them."""

import shutil
from pathlib import Path

import pytest

from pipeline.errors import InputError
from pipeline.inputs.sequence import load_sequence

SCEAUX = Path(__file__).parents[2] / "data" / "sceaux_castle_640"


def test_a_flat_folder_of_images_is_pointed_to_the_run_without_sequence(tmp_path):
    # it said only '0 robot sub-folder(s) holding images; a team needs at least two'
    for f in sorted(SCEAUX.glob("*.JPG"))[:3]:
        shutil.copy(f, tmp_path / f.name)
    with pytest.raises(InputError) as err:
        load_sequence(tmp_path, max_size=64)
    assert str(err.value) == (
        f"--sequence {str(tmp_path)!r}: 0 robot sub-folder(s) holding images; a team needs at "
        "least two (one sub-folder of frames per robot); its 3 image(s) directly in it belong "
        "to no robot: to run them as one snapshot of a team, drop --sequence")


def test_a_folder_without_images_is_told_only_what_a_team_needs(tmp_path):
    (tmp_path / "notes.txt").write_text("x")
    with pytest.raises(InputError, match=r"a team needs at least two \(one sub-folder of frames "
                                         r"per robot\)$"):
        load_sequence(tmp_path, max_size=64)
