"""A JPEG photograph saved as .jfif (as a browser on Windows saves one) or .jpe was left out
with a warning to convert it to one of .jpg, .jpeg, …: it is a JPEG file, and it is now
read as one."""


from noise_photos import noise_photos

from pipeline.inputs.photos import load_folder


def test_jfif_and_jpe_files_are_read_as_jpegs(tmp_path, caplog):
    d = tmp_path / "downloads"
    noise_photos(d, ("a.jfif", "b.JPE", "c.jpg"), fmt="JPEG")
    with caplog.at_level("WARNING", logger="pipeline"):
        views = load_folder(d, max_size=None)
    assert [v.name for v in views] == ["a.jfif", "b.JPE", "c.jpg"]
    assert not [r for r in caplog.records if r.levelname == "WARNING"]
