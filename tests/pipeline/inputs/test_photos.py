"""pipeline.inputs.photos: image folders, intrinsics (K.txt / EXIF / guess)."""

import shutil

import cv2
import numpy as np
import pytest
from PIL import ExifTags, Image

from pipeline.errors import InputError
from pipeline.inputs.photos import (
    GUESS_FOCAL_FACTOR,
    _scaled_K,
    exif_focal_px,
    load_folder,
    read_k_txt,
)


def _texture(h, w, seed=0):
    rng = np.random.default_rng(seed)
    return (rng.random((h, w, 3)) * 255).astype(np.uint8)


def _folder(tmp_path, images: dict):
    """Write ``{name: PIL image or bytes}`` into a fresh folder."""
    d = tmp_path / "imgs"
    d.mkdir()
    for name, im in images.items():
        if isinstance(im, bytes):
            (d / name).write_bytes(im)
        else:
            im.save(d / name)
    return d


# --------------------------------------------------------------------------- Sceaux, downscaled

def test_sceaux_folder_loads_in_name_order_with_scaled_k(sceaux_small):
    views = load_folder(sceaux_small, max_size=320)
    assert [v.name for v in views] == sorted(p.name for p in sceaux_small.glob("*.JPG"))
    K640 = np.loadtxt(sceaux_small / "K.txt")
    for v in views:
        w, h = v.size
        assert max(w, h) == 320 and v.image.dtype == np.uint8 and v.image.shape == (h, w, 3)
        assert v.intrinsics_source == "K.txt" and v.intrinsics_known
        assert v.R is None and v.t is None
        sx, sy = w / 640, h / 481
        assert v.K[0, 0] == pytest.approx(K640[0, 0] * sx)
        assert v.K[1, 1] == pytest.approx(K640[1, 1] * sy)
        assert v.K[0, 2] == pytest.approx((K640[0, 2] + 0.5) * sx - 0.5)


def test_sceaux_explicit_k_file_equals_auto(sceaux_small):
    auto = load_folder(sceaux_small, max_size=None)
    explicit = load_folder(sceaux_small, max_size=None, intrinsics=sceaux_small / "K.txt")
    assert all(np.array_equal(a.K, b.K) for a, b in zip(auto, explicit, strict=True))
    assert auto[0].size == (640, 481)  # max_size=None keeps the stored resolution


def test_scaled_k_hand_computed():
    # 100 px wide image, principal point at its centre (49.5); halved -> centre of 50 px (24.5)
    K = np.array([[100.0, 0, 49.5], [0, 80.0, 29.5], [0, 0, 1]])
    Ks = _scaled_K(K, 0.5, 0.5)
    assert np.allclose(Ks, [[50, 0, 24.5], [0, 40, 14.5], [0, 0, 1]])


# ------------------------------------------------------------------------------ pixel formats

def test_every_pixel_format_becomes_uint8(tmp_path):
    rgb = _texture(60, 80)
    deep = (np.linspace(0, 4095, 60 * 80).reshape(60, 80)).astype(np.uint16)  # 12-bit data
    d = _folder(tmp_path, {
        "a_gray.png": Image.fromarray(rgb[..., 0], "L"),
        "b_rgb.jpg": Image.fromarray(rgb, "RGB"),
        "c_rgba.png": Image.fromarray(np.dstack([rgb, np.full((60, 80), 128, np.uint8)]), "RGBA"),
        "d_16bit.png": Image.fromarray(deep),
        "e_16bit.tif": Image.fromarray(deep),
        "f_palette.png": Image.fromarray(rgb, "RGB").convert("P"),
    })
    views = load_folder(d)
    assert [v.name for v in views] == sorted(p.name for p in d.iterdir())
    shapes = {v.name: v.image.shape for v in views}
    assert shapes["a_gray.png"] == (60, 80)
    assert shapes["c_rgba.png"] == (60, 80, 3) and shapes["f_palette.png"] == (60, 80, 3)
    assert all(v.image.dtype == np.uint8 for v in views)
    for name in ("d_16bit.png", "e_16bit.tif"):
        img = next(v.image for v in views if v.name == name)
        assert img.min() == 0 and img.max() == 255  # stretched, not divided by 257
    assert np.array_equal(next(v.image for v in views if v.name == "c_rgba.png"), rgb)


def test_guess_when_no_exif_and_downscale(tmp_path):
    d = _folder(tmp_path, {"x.png": Image.fromarray(_texture(300, 400)),
                           "y.png": Image.fromarray(_texture(300, 400, 1))})
    views = load_folder(d, max_size=200)
    for v in views:
        assert v.size == (200, 150)
        assert not v.intrinsics_known and v.intrinsics_source == "guess"
        # guess at full size f = 1.2 * 400 = 480, scaled by 0.5; centre of the 200x150 image
        assert v.K[0, 0] == pytest.approx(GUESS_FOCAL_FACTOR * 400 * 0.5)
        assert v.K[0, 2] == pytest.approx(99.5) and v.K[1, 2] == pytest.approx(74.5)


def _jpeg_with_exif(path, rgb, **tags):
    exif = Image.Exif()
    sub = exif.get_ifd(0x8769)
    sub.update({getattr(ExifTags.Base, k).value: v for k, v in tags.items()})
    Image.fromarray(rgb).save(path, exif=exif)


def test_exif_35mm_equivalent(tmp_path):
    d = tmp_path / "exif"
    d.mkdir()
    rgb = _texture(300, 400)
    for name in ("a.jpg", "b.jpg"):
        _jpeg_with_exif(d / name, rgb, FocalLengthIn35mmFilm=28)
    views = load_folder(d, intrinsics="exif")
    expected = 28 * np.hypot(400, 300) / np.hypot(36, 24)
    assert views[0].K[0, 0] == pytest.approx(expected)
    assert views[0].intrinsics_known and views[0].intrinsics_source == "exif-35mm"


def test_exif_focal_plane_route(tmp_path):
    path = tmp_path / "fp.jpg"
    # 5 mm lens, 200 px per mm on the sensor, photo resized from 800 to 400 px wide
    _jpeg_with_exif(path, _texture(300, 400), FocalLength=5.0, FocalPlaneXResolution=200.0,
                    FocalPlaneResolutionUnit=4, ExifImageWidth=800)
    with Image.open(path) as im:
        f, source = exif_focal_px(im, 400, 300)
    assert source == "exif-focal-plane" and f == pytest.approx(5.0 * 200 * 0.5)


def test_exif_mode_without_exif_is_an_error(tmp_path):
    d = _folder(tmp_path, {"a.png": Image.fromarray(_texture(40, 50)),
                           "b.png": Image.fromarray(_texture(40, 50))})
    with pytest.raises(InputError, match=r"a\.png: no EXIF focal length"):
        load_folder(d, intrinsics="exif")


# ------------------------------------------------------------------------------------ bad input

def test_missing_folder(tmp_path):
    with pytest.raises(InputError, match="does not exist"):
        load_folder(tmp_path / "nope")


def test_empty_folder(tmp_path):
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="no images"):
        load_folder(tmp_path / "empty")


def test_folder_with_only_text_files_is_empty(tmp_path):
    d = _folder(tmp_path, {"notes.txt": b"hello"})
    with pytest.raises(InputError, match="no images"):
        load_folder(d)


def test_one_image_only(tmp_path):
    d = _folder(tmp_path, {"solo.png": Image.fromarray(_texture(40, 50))})
    with pytest.raises(InputError, match=r"only one image .*solo\.png"):
        load_folder(d)


def test_bmp_and_webp_photographs_are_read(tmp_path):
    """BMP and WebP were dropped by their suffix (an info line only, none with -q)."""
    d = _folder(tmp_path, {"a.png": Image.fromarray(_texture(40, 50, 1)),
                           "b.bmp": Image.fromarray(_texture(40, 50, 2)),
                           "c.webp": Image.fromarray(_texture(40, 50, 3))})
    assert [v.name for v in load_folder(d)] == ["a.png", "b.bmp", "c.webp"]


def test_what_looks_like_a_photograph_but_is_left_out_is_warned(tmp_path, caplog):
    """A GIF, a symbolic link leading nowhere and a sub-folder of images were dropped without
    a word (the link and the sub-folder even without --quiet); the one-image error names them."""
    d = _folder(tmp_path, {"a.png": Image.fromarray(_texture(40, 50, 1)),
                           "b.png": Image.fromarray(_texture(40, 50, 2)),
                           "c.gif": Image.fromarray(_texture(40, 50, 3)).convert("P")})
    (d / "dead.png").symlink_to(tmp_path / "nowhere.png")
    (d / "robot1").mkdir()
    Image.fromarray(_texture(40, 50, 4)).save(d / "robot1" / "f0.png")
    with caplog.at_level("WARNING", logger="pipeline"):
        assert [v.name for v in load_folder(d)] == ["a.png", "b.png"]
    warned = " ".join(r.getMessage() for r in caplog.records if r.levelname == "WARNING")
    for needle in ("1 image file(s) of a format not read here left out (c.gif",
                   "1 symbolic link(s) leading nowhere left out (dead.png)",
                   "1 sub-folder(s) holding images left out (robot1; one sub-folder of frames "
                   "per robot is --sequence)"):
        assert needle in warned, warned
    (d / "b.png").unlink()
    with pytest.raises(InputError, match=r"only one image .*a\.png.*c\.gif.*dead\.png"):
        load_folder(d)


def test_non_image_file_with_image_suffix(tmp_path):
    d = _folder(tmp_path, {"a.png": Image.fromarray(_texture(40, 50)),
                           "b.jpg": b"this is a text file, not a JPEG\n"})
    with pytest.raises(InputError, match=r"b\.jpg: cannot read it as an image"):
        load_folder(d)


def test_a_float_rgb_tiff_is_named_as_a_layout_not_read(tmp_path):
    """A valid 32-bit float RGB TIFF (Pillow cannot open it, OpenCV can) was called 'a
    truncated or non-image file'; its layout is named, with what to convert it to. A TIFF
    cut inside its header is still a truncated file."""
    from pipeline.inputs.photos import load_image

    rgb = _texture(40, 50).astype(np.float32) / 255
    assert cv2.imwrite(str(tmp_path / "f.tif"), rgb)
    assert cv2.imread(str(tmp_path / "f.tif"), cv2.IMREAD_UNCHANGED).dtype == np.float32
    with pytest.raises(InputError) as e:
        load_image(tmp_path / "f.tif")
    assert str(e.value) == ("f.tif: 32-bit floating-point TIFF, 3 sample(s) per pixel: not a "
                            "layout this reader decodes; convert it to an 8- or 16-bit PNG or "
                            "TIFF (e.g. magick f.tif -depth 16 f.png)")
    (tmp_path / "cut.tif").write_bytes((tmp_path / "f.tif").read_bytes()[:100])
    with pytest.raises(InputError, match=r"cut\.tif: cannot read it as an image"):
        load_image(tmp_path / "cut.tif")


def test_truncated_jpeg(tmp_path, sceaux_small):
    d = tmp_path / "trunc"
    d.mkdir()
    shutil.copy(sceaux_small / "100_7100.JPG", d / "100_7100.JPG")
    data = (sceaux_small / "100_7101.JPG").read_bytes()
    (d / "100_7101.JPG").write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match=r"100_7101\.JPG: cannot read it as an image"):
        load_folder(d)


def _off_centre_warnings(caplog):
    return [r.getMessage() for r in caplog.records if "lies far from the centre" in r.getMessage()]


def test_k_txt_of_the_full_resolution_beside_resized_copies_is_warned(tmp_path, caplog):
    """A K.txt for 640 px photos beside 320 px copies: its principal point fell inside the
    copies, so it was taken without a word (the reconstruction then registered nothing)."""
    d = _folder(tmp_path, {"a.png": Image.fromarray(_texture(241, 320, 1)),
                           "b.png": Image.fromarray(_texture(241, 320, 2))})
    (d / "K.txt").write_text("656 0 319.6\n0 656 240.1\n0 0 1\n")
    with caplog.at_level("WARNING", logger="pipeline"):
        load_folder(d, max_size=None)
    assert _off_centre_warnings(caplog) == [
        f"warning: {d / 'K.txt'}: principal point (319.6, 240.1) lies far from the centre of 2 "
        "image(s): a.png (320x241), b.png (320x241); is K.txt for another resolution? It must "
        "be at the files' resolution (for resized copies, scale fx, fy, cx and cy by the "
        "resize factor)"]


def test_k_txt_at_the_files_resolution_is_not_warned(tmp_path, caplog):
    d = _folder(tmp_path, {"a.png": Image.fromarray(_texture(240, 320, 1)),
                           "b.png": Image.fromarray(_texture(240, 320, 2))})
    (d / "K.txt").write_text("328 0 166\n0 328 114\n0 0 1\n")  # a few px off the centre
    with caplog.at_level("WARNING", logger="pipeline"):
        load_folder(d, max_size=None)
    assert _off_centre_warnings(caplog) == []


def test_file_names_that_are_not_utf8_are_refused(tmp_path):
    """A Latin-1 file name ('ch\\xe2teau.jpg') was loaded, then crashed the run with a
    traceback where COLMAP's database was written."""
    import os

    d = _folder(tmp_path, {"a.png": Image.fromarray(_texture(40, 50, 1))})
    Image.fromarray(_texture(40, 50, 2)).save(d / os.fsdecode(b"ch\xe2teau.png"))
    with pytest.raises(InputError, match=r"^1 image file name\(s\) in .* are not UTF-8 text "
                                         r"\('ch\\udce2teau\.png'\).*rename them"):
        load_folder(d)


def test_empty_file_is_named_as_empty(tmp_path):
    """A zero-byte file with an image suffix was refused as an unidentified image; it says
    the file is empty."""
    d = _folder(tmp_path, {"a.png": Image.fromarray(_texture(40, 50, 1)),
                           "b.png": Image.fromarray(_texture(40, 50, 2)),
                           "c.jpg": b""})
    with pytest.raises(InputError, match=r"^c\.jpg: the file is empty \(0 bytes\), not an image"):
        load_folder(d)


@pytest.mark.parametrize("name", ["pages.tif", "anim.webp"])
def test_frames_after_the_first_are_not_dropped_silently(tmp_path, caplog, name):
    """A multi-page TIFF or an animated WebP was read as its first frame without a word."""
    d = _folder(tmp_path, {"a.png": Image.fromarray(_texture(40, 50, 1))})
    frames = [Image.fromarray(_texture(40, 50, k)) for k in (2, 3, 4)]
    frames[0].save(d / name, save_all=True, append_images=frames[1:])
    with caplog.at_level("WARNING", logger="pipeline"):
        assert [v.name for v in load_folder(d)] == ["a.png", name]
    warned = " ".join(r.getMessage() for r in caplog.records if r.levelname == "WARNING")
    assert f"hold several frames or pages and only the first of each is read: {name} (3)" \
        in warned, warned


def test_single_frame_images_are_not_warned_as_multi_frame(tmp_path, caplog):
    d = _folder(tmp_path, {"a.png": Image.fromarray(_texture(40, 50, 1)),
                           "b.tif": Image.fromarray(_texture(40, 50, 2)),
                           "c.webp": Image.fromarray(_texture(40, 50, 3))})
    with caplog.at_level("WARNING", logger="pipeline"):
        load_folder(d)
    assert not [r for r in caplog.records if "several frames" in r.getMessage()]


@pytest.mark.parametrize("text, match", [
    ("fx 0 cx\n0 fy cy\n0 0 1\n", "'fx' is not a number"),
    ("1000 0 320\n0 1000 240\n", "holds 6 numbers"),
    ("1000 0 320\n0 1000 240\n0 1 1\n", "not a pinhole matrix"),
    ("-5 0 320\n0 1000 240\n0 0 1\n", "focal lengths must be positive"),
    ("", "holds 0 numbers"),
])
def test_k_txt_that_does_not_parse(tmp_path, text, match):
    k = tmp_path / "K.txt"
    k.write_text(text)
    with pytest.raises(InputError, match=match):
        read_k_txt(k)


def test_bad_k_txt_in_folder_stops_the_load(tmp_path):
    d = _folder(tmp_path, {"a.png": Image.fromarray(_texture(40, 50)),
                           "b.png": Image.fromarray(_texture(40, 50)), "K.txt": b"1 2 3\n"})
    with pytest.raises(InputError, match="holds 3 numbers"):
        load_folder(d)


def test_k_txt_four_numbers_and_comments(tmp_path):
    k = tmp_path / "K.txt"
    k.write_text("# fx fy cx cy\n500, 510, 320, 240\n")
    assert np.allclose(read_k_txt(k), [[500, 0, 320], [0, 510, 240], [0, 0, 1]])


def test_k_txt_saved_with_a_byte_order_mark(tmp_path):
    """Windows Notepad's "UTF-8 with BOM": the mark was read as part of fx, and the file
    refused as "'\\ufeff2905' is not a number"."""
    k = tmp_path / "K.txt"
    k.write_bytes(b"\xef\xbb\xbf2905 0 1416\r\n0 2905 1064\r\n0 0 1\r\n")
    assert np.allclose(read_k_txt(k), [[2905, 0, 1416], [0, 2905, 1064], [0, 0, 1]])


def test_k_txt_for_another_resolution(tmp_path):
    d = _folder(tmp_path, {"a.png": Image.fromarray(_texture(40, 50)),
                           "b.png": Image.fromarray(_texture(40, 50))})
    k = tmp_path / "K.txt"
    k.write_text("2905 0 1416\n0 2905 1064\n0 0 1\n")
    with pytest.raises(InputError, match="principal point .* outside image a.png"):
        load_folder(d, intrinsics=k)


@pytest.mark.parametrize("size", [0, 8, 12.5, True])
def test_bad_max_size(tmp_path, size):
    with pytest.raises(InputError, match="max_size"):
        load_folder(tmp_path, max_size=size)


def test_content_order_follows_the_pixels_not_the_names():
    from pipeline.inputs.photos import in_content_order
    from pipeline.types import View

    rng = np.random.default_rng(5)
    images = [rng.integers(0, 255, (8, 8, 3), dtype=np.uint8) for _ in range(5)]
    views = [View(f"n{k}.png", im, np.eye(3)) for k, im in enumerate(images)]
    order = [v.image.tobytes() for v in in_content_order(views)]
    renamed = [View(f"z{9 - k}.png", im, np.eye(3)) for k, im in enumerate(images)]
    assert [v.image.tobytes() for v in in_content_order(renamed[::-1])] == order
    # identical pixels keep their name order
    twins = [View("b.png", images[0], np.eye(3)), View("a.png", images[0].copy(), np.eye(3))]
    assert [v.name for v in in_content_order(twins)] == ["a.png", "b.png"]


def test_identical_photographs_are_found_by_their_pixels(sceaux_small, tmp_path):
    from pipeline.inputs.photos import identical_pixels, load_folder

    files = sorted(p for p in sceaux_small.iterdir() if p.suffix.lower() == ".jpg")[:3]
    for p in files:
        shutil.copy(p, tmp_path / p.name)
    assert identical_pixels(load_folder(tmp_path, max_size=64)) == []
    shutil.copy(files[1], tmp_path / "copy.jpg")   # the same photograph under another name
    assert identical_pixels(load_folder(tmp_path, max_size=64)) == [
        sorted(["copy.jpg", files[1].name])]
