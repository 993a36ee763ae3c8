"""Fuzzed intrinsics of ``run-images``: a damaged K.txt, and EXIF tags of any type and value,
give views with a usable K or an InputError naming the file."""

import re
import struct
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from PIL import ExifTags, Image, TiffImagePlugin

from pipeline.errors import InputError
from pipeline.inputs.photos import load_folder

sys.path.insert(0, str(Path(__file__).parents[1]))
from mutants import FUZZ, bytes_mutant, read_or_refuse, text_mutant  # noqa: E402

W, H = 64, 48
K_TXTS = ["70 0 31.5\n0 70 23.5\n0 0 1\n", "70, 72, 31.5, 23.5  # fx fy cx cy\n",
          "\ufeff70\t0.5\t31.5\n0\t70\t23.5\n0\t0\t1\n"]


def _images(folder: Path, exif=None) -> None:
    rng = np.random.default_rng(0)
    for name in ("a.jpg", "b.jpg"):
        im = Image.fromarray(rng.integers(0, 255, (H, W, 3), dtype=np.uint8))
        im.save(folder / name, exif=exif if exif is not None else Image.Exif())


def _check(views, folder) -> None:
    assert len(views) == 2
    for v in views:
        K = v.K
        assert K.shape == (3, 3) and np.isfinite(K).all() and K[0, 0] > 0 and K[1, 1] > 0
        assert 0 <= K[0, 2] <= W and 0 <= K[1, 2] <= H


@FUZZ
@given(st.one_of(st.sampled_from(K_TXTS).flatmap(text_mutant).map(
    lambda s: s.encode("utf-8", "surrogatepass")), bytes_mutant(K_TXTS[0].encode())))
def test_a_damaged_k_txt_gives_a_usable_k_or_an_error_naming_it(content):
    with tempfile.TemporaryDirectory() as d:
        folder = Path(d)
        _images(folder)
        (folder / "K.txt").write_bytes(content)
        views = read_or_refuse(lambda: load_folder(folder, max_size=None), "K.txt")
        if views is not None:
            _check(views, folder)
            assert {v.intrinsics_source for v in views} == {"K.txt"}
            # numbers written in digits 0-9 (Python's float() also reads "7_0" as 70, and
            # other scripts' digits)
            body = "".join(ln.split("#")[0] for ln in content.decode("utf-8-sig").splitlines())
            assert re.fullmatch(r"[0-9eE+.,;\s-]*", body), content


@pytest.mark.parametrize("fx", ["7_0", "\u0667\u0660"])
def test_a_k_txt_number_not_written_in_digits_is_refused(tmp_path, fx):
    _images(tmp_path)
    (tmp_path / "K.txt").write_text(f"{fx} 0 31.5\n0 70 23.5\n0 0 1\n")
    with pytest.raises(InputError, match=f"{fx!r} is not a number"):
        load_folder(tmp_path, max_size=None)


_RATIONALS = st.one_of(
    st.integers(-2**40, 2**40), st.floats(allow_nan=True, allow_infinity=True),
    st.tuples(st.integers(-2**33, 2**33), st.integers(-2**33, 2**33)).map(
        lambda t: TiffImagePlugin.IFDRational(*t)),
    st.text(max_size=4), st.binary(max_size=4), st.just(None),
    st.tuples(st.integers(0, 10**6), st.integers(0, 10**6)))
_TAGS = [ExifTags.Base.FocalLengthIn35mmFilm, ExifTags.Base.FocalLength,
         ExifTags.Base.FocalPlaneXResolution, ExifTags.Base.FocalPlaneResolutionUnit,
         ExifTags.Base.ExifImageWidth, ExifTags.Base.ExifImageHeight]


@FUZZ
@given(st.dictionaries(st.sampled_from(_TAGS), _RATIONALS, max_size=6),
       st.sampled_from(["exif", "auto"]))
def test_exif_tags_of_any_value_give_a_usable_k_or_an_error(tags, mode):
    with tempfile.TemporaryDirectory() as d:
        folder = Path(d)
        exif = Image.Exif()
        sub = exif.get_ifd(ExifTags.IFD.Exif)
        for tag, value in tags.items():
            sub[tag] = value
        try:
            _images(folder, exif)
        except (TypeError, ValueError, OverflowError, struct.error, KeyError):
            return  # a value PIL cannot write
        views = read_or_refuse(lambda: load_folder(folder, max_size=None, intrinsics=mode),
                               ".jpg")
        if views is not None:
            _check(views, folder)


@FUZZ
@given(st.data())
def test_a_damaged_exif_block_gives_a_usable_k_or_an_error(data):
    with tempfile.TemporaryDirectory() as d:
        folder = Path(d)
        exif = Image.Exif()
        sub = exif.get_ifd(ExifTags.IFD.Exif)
        sub[ExifTags.Base.FocalLength] = TiffImagePlugin.IFDRational(35, 1)
        sub[ExifTags.Base.FocalPlaneXResolution] = TiffImagePlugin.IFDRational(4000, 1)
        sub[ExifTags.Base.FocalPlaneResolutionUnit] = 2
        sub[ExifTags.Base.ExifImageWidth] = W
        block = exif.tobytes()
        _images(folder, data.draw(bytes_mutant(block)))
        views = read_or_refuse(lambda: load_folder(folder, max_size=None,
                                                   intrinsics=data.draw(st.sampled_from(
                                                       ["exif", "auto"]))), ".jpg")
        if views is not None:
            _check(views, folder)


@FUZZ
@given(st.sampled_from(["png", "jpg", "tif"]), st.data())
def test_a_damaged_image_file_is_read_or_refused(fmt, data):
    with tempfile.TemporaryDirectory() as d:
        folder = Path(d)
        rng = np.random.default_rng(0)
        for name in ("a", "b"):
            Image.fromarray(rng.integers(0, 255, (H, W, 3), dtype=np.uint8)).save(
                folder / f"{name}.{fmt}")
        path = folder / f"b.{fmt}"
        path.write_bytes(data.draw(bytes_mutant(path.read_bytes(), max_ops=3)))
        views = read_or_refuse(lambda: load_folder(folder, max_size=None), f".{fmt}")
        if views is not None:
            assert len(views) == 2
            for v in views:
                # a damaged header may declare another size, which the decoder fills
                assert v.image.dtype == np.uint8 and min(v.image.shape[:2]) >= 2
