"""``run-images DIR --sequence``: an error in ``DIR/K.txt``, which serves every robot without
a K.txt of its own, names that file as the folder's shared one, not the first robot."""
import shutil
from pathlib import Path

import pytest

from pipeline.errors import InputError
from pipeline.inputs.sequence import load_sequence

SCEAUX = Path(__file__).parents[2] / "data" / "sceaux_castle_640"
_GOOD_K = "500 0 300\n0 500 200\n0 0 1\n"


def _folder(root: Path) -> Path:
    files = sorted(SCEAUX.glob("*.JPG"))
    for r, robot in enumerate(("a", "b")):
        (root / robot).mkdir(parents=True)
        for k in range(2):
            shutil.copy(files[2 * r + k], root / robot / f"f{k:02d}.jpg")
    (root / "K.txt").write_text("1 2 3\n")
    return root


def test_a_bad_shared_k_txt_is_named_as_the_folder_s_not_a_robot_s(tmp_path):
    root = _folder(tmp_path / "seq")
    with pytest.raises(InputError) as exc:
        load_sequence(root, max_size=64)
    message = str(exc.value)
    assert message.startswith(f"--sequence {str(root)!r}: the folder's shared K.txt, serving "
                              "every robot without a K.txt of its own: intrinsics file "
                              f"{str(root / 'K.txt')!r} holds 3 numbers")
    assert "robot 'a'" not in message


def test_a_bad_intrinsics_file_is_named_as_serving_every_robot(tmp_path):
    root = _folder(tmp_path / "seq")
    with pytest.raises(InputError, match=r"^--sequence '.*seq': --intrinsics, serving every "
                                         r"robot: intrinsics file '.*seq/K\.txt' holds 3"):
        load_sequence(root, max_size=64, intrinsics=root / "K.txt")


def test_a_robot_s_own_bad_k_txt_is_named_by_its_path(tmp_path):
    root = _folder(tmp_path / "seq")
    (root / "K.txt").write_text(_GOOD_K)
    (root / "b" / "K.txt").write_text("1 2 3\n")
    with pytest.raises(InputError, match=r"^intrinsics file '.*seq/b/K\.txt' holds 3 numbers"):
        load_sequence(root, max_size=64)


def test_a_shared_k_txt_that_serves_no_robot_is_not_read(tmp_path):
    root = _folder(tmp_path / "seq")
    for robot in ("a", "b"):
        (root / robot / "K.txt").write_text(_GOOD_K)
    assert load_sequence(root, max_size=64).steps == 2
