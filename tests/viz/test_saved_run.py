"""Tests of viz.saved_run: a saved run folder read back and logged like the run itself."""

from __future__ import annotations

import json

import numpy as np
import pytest
from test_rerun_log import N_DELETED, make_record

from pipeline import colmap
from pipeline.errors import InputError
from pipeline.inputs.linkscsv import write_links_csv
from viz.recording_reader import count_strips
from viz.saved_run import log_run_folder, main, read_run_folder


def _save(record, folder):
    folder.mkdir()
    write_links_csv(folder / "links.csv", record.ledger)
    colmap.write_model(folder / "sparse",
                       colmap.build_reconstruction(record.views, record.features))
    (folder / "report.json").write_text(json.dumps(
        {"n_cameras": len(record.views),
         "features_per_camera": [len(f) for f in record.features]}))
    return folder


def test_read_back_what_the_run_wrote(tmp_path):
    record = make_record()
    back = read_run_folder(_save(record, tmp_path / "run"))
    for name in ("status", "reason", "round"):
        assert getattr(back.ledger, name).tolist() == getattr(record.ledger, name).tolist()
    assert back.ledger.links.feat_j.tolist() == record.ledger.links.feat_j.tolist()
    for v, w, f, g in zip(back.views, record.views, back.features, record.features, strict=True):
        assert v.name == w.name and v.size == w.size
        np.testing.assert_allclose(v.K, w.K, atol=1e-9)
        np.testing.assert_allclose(v.R, w.R, atol=1e-9)
        np.testing.assert_allclose(v.t, w.t, atol=1e-9)
        np.testing.assert_allclose(f.keypoints, g.keypoints, atol=1e-4)


def test_the_conflictive_sets_before_are_those_of_every_link(tmp_path):
    """links.csv lists every link matching produced: the links in conflictive sets before the
    resolution are recomputed from it, as the run computed them (the recording said '0 links
    lay in conflictive sets' beside a cut 'in a conflictive set')."""
    from pipeline.association import conflictive_links
    from viz.rerun_log import cut_summary

    record = make_record()
    back = read_run_folder(_save(record, tmp_path / "run"))
    m = [len(f) for f in record.features]
    want = conflictive_links(m, record.ledger.links)
    assert want.any()  # the case this test is about
    assert back.ledger.conflictive_before.tolist() == want.tolist()
    assert f"{int(want.sum())} links lay in conflictive sets" in cut_summary(back)


def test_log_a_folder_without_recording(tmp_path, capsys):
    folder = _save(make_record(), tmp_path / "run")
    assert main([str(folder)]) == 0
    path = folder / "recording.rrd"
    assert count_strips(path, "world/links/deleted") == N_DELETED
    with pytest.raises(InputError, match="exists"):
        log_run_folder(folder)  # never replaces the run's own recording
    assert main([str(tmp_path)]) == 2
    assert "no report.json" in capsys.readouterr().err


def test_a_recording_added_to_a_run_folder_keeps_it_replaceable(tmp_path):
    """The recording is the run's own output: the folder's marker lists it, so a next run
    may still replace the folder; a folder holding a user's file stays protected."""
    from pipeline.outputs import run_folder_problem
    from pipeline.runfolder import atomic_run_folder

    record = make_record()
    run = tmp_path / "run"
    with atomic_run_folder(run) as staged:
        _save(record, staged / "x")
        for p in (staged / "x").iterdir():
            p.rename(staged / p.name)
        (staged / "x").rmdir()
    log_run_folder(run)
    assert (run / "recording.rrd").is_file() and run_folder_problem(run) is None
    (run / "recording.rrd").unlink()
    (run / "notes.txt").write_text("mine")
    log_run_folder(run)
    assert "notes.txt" in run_folder_problem(run)


def test_out_must_be_a_recording_and_online_folders_are_said(tmp_path, capsys):
    """--out naming the run's own links.csv (or any file not .rrd) is refused and the folder
    stays readable (it once overwrote links.csv with the recording); an online run folder is
    named as such, not 'not a run folder'."""
    folder = _save(make_record(), tmp_path / "run")
    before = (folder / "links.csv").read_bytes()
    for out in (folder / "links.csv", folder / "report.json", tmp_path / "rec.txt"):
        assert main([str(folder), "--out", str(out)]) == 2
        assert "a recording is written to a .rrd file" in capsys.readouterr().err
    assert (folder / "links.csv").read_bytes() == before
    read_run_folder(folder)
    online = tmp_path / "online"
    online.mkdir()
    for name in ("report.json", "links.csv", "images.csv", "link_steps.csv"):
        (online / name).write_text("")
    assert main([str(online)]) == 2
    assert "an online run folder" in capsys.readouterr().err


def test_an_online_folder_with_its_recording_is_said_online_before_the_output(tmp_path, capsys):
    """An online run writes recording.rrd: the folder is named online and its recording
    pointed at, not 'recording.rrd exists; name another file with --out' (which, followed,
    led to the online refusal)."""
    online = tmp_path / "online"
    online.mkdir()
    for name in ("report.json", "links.csv", "images.csv", "link_steps.csv", "recording.rrd"):
        (online / name).write_text("")
    assert main([str(online)]) == 2
    err = capsys.readouterr().err
    assert "an online run folder" in err and "exists" not in err
    assert f"make view RUN={online}" in err
    assert main([str(online), "--out", str(tmp_path / "other.rrd")]) == 2
    assert "an online run folder" in capsys.readouterr().err
    assert not (tmp_path / "other.rrd").exists()


def test_a_folder_whose_files_do_not_read_is_said_not_a_traceback(tmp_path, capsys):
    """A report.json that is not JSON or not a run's report, and a sparse/ without its model
    files, are input errors (exit 2 and a message), not a traceback."""
    cases = {
        "not-json": lambda f: (f / "report.json").write_text("{"),
        "no-features": lambda f: (f / "report.json").write_text('{"n_cameras": 3}'),
        "a-list": lambda f: (f / "report.json").write_text("[]"),
        "no-model": lambda f: (f / "sparse" / "points3D.bin").unlink(),
    }
    for name, spoil in cases.items():
        folder = _save(make_record(), tmp_path / name)
        spoil(folder)
        with pytest.raises(InputError):
            read_run_folder(folder)
        assert main([str(folder)]) == 2, name
        assert "error:" in capsys.readouterr().err
        assert not (folder / "recording.rrd").exists()


def test_a_ctrl_c_is_one_line_and_exit_130_not_a_traceback(tmp_path, capsys, monkeypatch):
    """Ctrl-C while the recording is written ends as the pipeline's commands end: one
    'interrupted: …' line on stderr and exit code 130."""
    import viz.saved_run

    folder = _save(make_record(), tmp_path / "run")

    def interrupted(*_args, **_kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(viz.saved_run, "log_run_folder", interrupted)
    try:
        code = main([str(folder)])
    except KeyboardInterrupt:
        pytest.fail("the Ctrl-C escaped viz.saved_run.main (a traceback, death by SIGINT)")
    assert code == 130
    err = capsys.readouterr().err
    assert err.startswith("interrupted: viz.saved_run stopped")
    assert len(err.strip().splitlines()) == 1
    assert not (folder / "recording.rrd").exists()


def test_a_ctrl_c_after_the_recording_is_written_names_it(tmp_path, capsys, monkeypatch):
    """Ctrl-C while 'wrote …' is printed: the recording is in place, whole, and the
    interrupt line says so instead of 'nothing was written or replaced'."""
    import viz.saved_run

    folder = _save(make_record(), tmp_path / "run")

    def interrupted(*_args, **_kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(viz.saved_run, "say", interrupted)
    assert main([str(folder)]) == 130
    err = capsys.readouterr().err
    assert err == (f"interrupted: viz.saved_run stopped; already in place, complete: "
                   f"{str(folder / 'recording.rrd')!r}\n")
    assert count_strips(folder / "recording.rrd", "world/links/deleted") == N_DELETED


def test_a_ctrl_c_while_the_libraries_load_is_one_line_and_exit_130(tmp_path):
    """Run as a program, a Ctrl-C before main (here: raised by the import of NumPy, a
    stand-in module first on the path) ends with the one line, no traceback."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    (tmp_path / "numpy.py").write_text("raise KeyboardInterrupt\n")
    root = Path(__file__).resolve().parents[2]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), str(root)])}
    out = subprocess.run([sys.executable, "-m", "viz.saved_run", str(tmp_path / "run")],
                         cwd=root, capture_output=True, text=True, env=env)
    assert out.stderr == "interrupted: viz.saved_run stopped, nothing was written or replaced\n"
    assert out.returncode == 130


def test_an_empty_out_is_named_as_empty(tmp_path, capsys):
    """--out "$UNSET" was refused as "--out '.': a recording is written to a .rrd file", a
    value the user never gave."""
    folder = _save(make_record(), tmp_path / "run")
    assert main([str(folder), "--out", ""]) == 2
    assert capsys.readouterr().err == ("error: --out '' is empty (an unset variable?); name a "
                                       ".rrd file, or drop --out to write RUN_DIR/recording.rrd\n")
    assert not (folder / "recording.rrd").exists()


def test_a_landmarks_run_and_a_missing_folder_are_named(tmp_path, capsys):
    """A run-landmarks folder (report.json, links.csv, no sparse/) is named as such, not 'no
    sparse; not a run folder'; a folder that does not exist is named missing, not 'no
    report.json'."""
    run = tmp_path / "lm"
    run.mkdir()
    (run / "report.json").write_text('{"feature_landmarks": [[0, 1]]}')
    (run / "links.csv").write_text("")
    assert main([str(run)]) == 2
    err = capsys.readouterr().err
    assert "a run-landmarks run folder" in err and "writes no recording" in err
    assert not (run / "recording.rrd").exists()
    assert main([str(tmp_path / "no-such")]) == 2
    assert f"{tmp_path / 'no-such'}: no such folder; give the run folder" in \
        capsys.readouterr().err


def test_a_report_whose_feature_counts_are_not_counts_is_said_not_a_traceback(tmp_path, capsys):
    """report.json's features_per_camera of null, strings or a number raised TypeError /
    ValueError; links.csv naming a camera the report does not list was said without the
    file. Both are now one 'error:' line naming the file (exit 2), and nothing is written."""
    for name, value in (("null", None), ("strings", ["a", "b", "c"]), ("number", 3),
                        ("negative", [-1, 16, 16]), ("booleans", [True, True, True])):
        folder = _save(make_record(), tmp_path / name)
        report = json.loads((folder / "report.json").read_text())
        report["features_per_camera"] = value
        (folder / "report.json").write_text(json.dumps(report))
        assert main([str(folder)]) == 2, name
        err = capsys.readouterr().err
        assert err.startswith("error: ") and err.count("\n") == 1, err
        assert "features_per_camera" in err, err
        assert not (folder / "recording.rrd").exists()
    folder = _save(make_record(), tmp_path / "other-links")
    lines = (folder / "links.csv").read_text().splitlines()
    lines[1] = "7," + lines[1].split(",", 1)[1]  # camera 7 of a 3-camera run
    (folder / "links.csv").write_text("\n".join(lines) + "\n")
    assert main([str(folder)]) == 2
    err = capsys.readouterr().err
    assert "links.csv" in err and "camera id out of range" in err, err


def test_a_recording_it_cannot_write_is_said_before_any_work(tmp_path, capsys):
    """An --out under a file, or a run folder without write permission, raised
    NotADirectoryError / RuntimeError from the recording stream as a traceback, after the
    folder was read; now one 'error:' line naming the place (exit 2), before any work."""
    import os
    import stat

    folder = _save(make_record(), tmp_path / "run")
    (tmp_path / "a-file").write_text("x")
    assert main([str(folder), "--out", str(tmp_path / "a-file" / "x.rrd")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: --out") and "is a file, not a folder" in err, err
    assert err.count("\n") == 1
    folder.chmod(stat.S_IRUSR | stat.S_IXUSR)
    try:
        try:
            (folder / "probe").touch()
        except OSError:
            pass
        else:
            (folder / "probe").unlink()
            pytest.skip("this user writes in a folder without write permission (root)")
        assert main([str(folder)]) == 2
        err = capsys.readouterr().err
        assert err.startswith("error: the recording") and "cannot write in" in err, err
        assert "--out FILE.rrd" in err and err.count("\n") == 1
        assert sorted(os.listdir(folder)) == ["links.csv", "report.json", "sparse"]
    finally:
        folder.chmod(stat.S_IRWXU)


def _photo_report(record) -> dict:
    """What a run-images report says of its images (read for the unregistered ones)."""
    return {"n_cameras": len(record.views),
            "features_per_camera": [len(f) for f in record.features],
            "images": [{"name": v.name, "size": list(v.size), "K": v.K.tolist()}
                       for v in record.views],
            "config": {"features": "sift"},
            "before": {"links": 1}, "after": {"links": 1}, "resolution": {}}


def _photo_run(tmp_path, spoil):
    """A saved run folder whose report.json is a photo run's (:func:`_photo_report`) as
    ``spoil(report)`` leaves it; the folder and its record."""
    record = make_record()
    folder = _save(record, tmp_path / "run")
    report = _photo_report(record)
    spoil(report)
    (folder / "report.json").write_text(json.dumps(report))
    return folder, record


@pytest.mark.parametrize("spoil, said", [
    (lambda r: r.update(images=None), "images is 'None', not a list"),
    (lambda r: r.update(images=[1, 2, 3]), "entry 0 is '1', not an object"),
    (lambda r: r["images"][1].pop("name"), "entry 1 has no image name"),
    (lambda r: r["images"][0].update(size="x"), "has size 'x'"),
    (lambda r: r["images"][0].pop("size"), "has size 'None'"),
    (lambda r: r["images"][2].update(K=None), "has K 'None'"),
    (lambda r: r["images"][2].update(K=[[0, 0, 0], [0, 0, 0], [0, 0, 1]], name="unregistered"),
     "not an invertible 3 x 3 camera matrix"),
])
def test_a_report_whose_images_do_not_read_is_said_not_a_traceback(tmp_path, capsys, spoil,
                                                                    said):
    """A photo run's report.json whose images section was not a list of {name, size, K}
    raised TypeError / KeyError / IndexError; now one 'error:' line naming the entry."""
    folder, _ = _photo_run(tmp_path, spoil)
    assert main([str(folder)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1 and said in err, err
    assert not (folder / "recording.rrd").exists()


@pytest.mark.parametrize("spoil", [lambda r: r.update(config=None),
                                   lambda r: r.update(before=None),
                                   lambda r: r.update(fusion=[1])])
def test_report_sections_that_are_not_objects_leave_the_report_panel_out(tmp_path, spoil):
    """A config or a before / after / fusion section that is not an object raised
    AttributeError / TypeError; what the recording reads of them is optional."""
    folder, _ = _photo_run(tmp_path, spoil)
    assert main([str(folder)]) == 0
    assert count_strips(folder / "recording.rrd", "world/links/deleted") == N_DELETED


@pytest.mark.parametrize("name", ["report.json", "links.csv"])
def test_a_fifo_or_folder_in_place_of_a_run_file_is_said_not_read(tmp_path, capsys, name):
    """A FIFO named report.json or links.csv was opened and read: viz.saved_run (and
    viz.view, asking whether the folder is a run-landmarks one) blocked for ever; a folder
    named report.json raised IsADirectoryError. Now one 'error:' line, exit 2."""
    import os

    from viz.view import main as view_main

    for kind in ("fifo", "folder"):
        folder = _save(make_record(), tmp_path / f"{kind}-{name}")
        (folder / name).unlink()
        os.mkfifo(folder / name) if kind == "fifo" else (folder / name).mkdir()
        assert main([str(folder)]) == 2
        err = capsys.readouterr().err
        assert f"its {name} is not a regular file" in err and err.count("\n") == 1, err
        assert view_main([str(folder), "--dry-run"]) == 2
        assert "no recording.rrd" in capsys.readouterr().err


def test_an_image_larger_than_any_run_reads_is_refused_not_allocated(tmp_path, capsys):
    """The recording draws each camera on a blank image of its size: a report.json size of
    100000 x 100000 made viz.saved_run allocate 10 GB (killed by the kernel). A size above
    what a run reads (pipeline.inputs.photos.MAX_IMAGE_PIXELS) is now an input error."""
    from pipeline.inputs.photos import MAX_IMAGE_PIXELS

    folder, _ = _photo_run(tmp_path, lambda r: r["images"][2].update(
        name="unregistered", size=[20_000, MAX_IMAGE_PIXELS // 20_000 + 1]))
    assert main([str(folder)]) == 2
    err = capsys.readouterr().err
    assert "camera 2 (unregistered) is 20000 x 5001 pixels in report.json" in err, err
    assert err.count("\n") == 1 and not (folder / "recording.rrd").exists()


def test_a_feature_count_beyond_the_image_is_refused_before_any_allocation(tmp_path, capsys):
    """report.json's features_per_camera sized every per-feature array: the conflictive sets
    were computed over them before any count was checked (10**9 features for one camera
    asked numpy for 3.7 GiB, then more), and an unregistered image got that many unknown
    keypoints. Counts are now checked first: against sparse/ for a registered image, against
    the image's pixels for one the mapper did not register."""
    def spoil(report):
        report["images"][2]["name"] = "unregistered"
        report["features_per_camera"][2] = 10**6  # more than its 320 x 240 pixels

    folder, record = _photo_run(tmp_path, spoil)
    assert main([str(folder)]) == 2
    err = capsys.readouterr().err
    assert "camera 2 (unregistered) has 1,000,000 features in report.json, more than its " \
           "320 x 240 pixels" in err, err
    report = json.loads((folder / "report.json").read_text())
    report["images"][2]["name"] = record.views[2].name
    (folder / "report.json").write_text(json.dumps(report))
    assert main([str(folder)]) == 2
    assert "keypoints in sparse/ but 1000000 features in report.json" in capsys.readouterr().err


def test_an_empty_run_dir_is_named_as_empty_not_read_as_the_current_folder(tmp_path, capsys,
                                                                         monkeypatch):
    """python -m viz.saved_run "$UNSET" read the current folder (Path('') is '.') and, in a
    run folder, wrote its recording there; now 'RUN_DIR '' is empty', exit 2."""
    folder = _save(make_record(), tmp_path / "run")
    monkeypatch.chdir(folder)
    assert main([""]) == 2
    assert capsys.readouterr().err.startswith("error: RUN_DIR '' is empty")
    assert not (folder / "recording.rrd").exists()
