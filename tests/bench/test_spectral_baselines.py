"""bench/spectral_baselines.py --json: a failed write leaves the previous file whole."""

import json
import resource
import signal
from pathlib import Path

import pytest
from benchload import load_bench

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data" / "cmu_hotel_small"


def _bench():
    return load_bench("spectral_baselines")


def _args(path):
    return ["--data", str(DATA), "--frames", "6", "--graphs", "ring2", "--descriptors", "given",
            "--json", str(path)]


def test_json_is_saved(tmp_path, capsys):
    path = tmp_path / "records.json"
    assert _bench().main(_args(path)) == 0
    assert json.loads(path.read_text())["records"]


def test_a_write_that_fails_keeps_the_previous_file(tmp_path, monkeypatch, capsys):
    path = tmp_path / "records.json"
    previous = json.dumps({"seed": 0, "records": list(range(1000))})
    path.write_text(previous)
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    handler = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    getrusage = resource.getrusage

    def getrusage_then_disk_full(who):
        # read just before the file is saved: from here on no file of this process may grow
        # past 200 bytes (EFBIG), the write fails part-way, as on a full disk
        usage = getrusage(who)
        resource.setrlimit(resource.RLIMIT_FSIZE, (200, hard))
        return usage

    monkeypatch.setattr(resource, "getrusage", getrusage_then_disk_full)
    try:
        with pytest.raises(OSError):
            _bench().main(_args(path))
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
        signal.signal(signal.SIGXFSZ, handler)
    assert path.read_text() == previous
    assert [p.name for p in tmp_path.iterdir()] == ["records.json"]


@pytest.mark.parametrize("args, message", [
    (["--data", "NOPE"], "error: NOPE: no such folder of labelled images"),
    (["--frames", "1"], "error: --frames 1: expected 2.."),
])
def test_input_it_cannot_read_is_one_error_line(tmp_path, capsys, args, message):
    argv = _args(tmp_path / "records.json")
    for flag, value in zip(args[::2], args[1::2], strict=True):
        argv[argv.index(flag) + 1] = value
    assert _bench().main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(message) and "Traceback" not in err
    assert not (tmp_path / "records.json").exists()


@pytest.mark.parametrize("where", ["under a file", "a folder"])
def test_a_json_path_it_cannot_write_is_refused_first(tmp_path, capsys, where):
    (tmp_path / "f").write_text("mine")
    path = tmp_path / "f" / "records.json" if where == "under a file" else tmp_path
    assert _bench().main(_args(path)) == 2
    out, err = capsys.readouterr()
    assert err.startswith(f"error: --json {str(path)!r}") and "Traceback" not in err
    assert out == "" and (tmp_path / "f").read_text() == "mine"


@pytest.mark.parametrize("args, message", [
    # spectral_sync's ValueError traceback, after the first method had run
    (["--universe", "0"], "argument --universe: '0': expected a whole number of at least 1"),
    (["--universe", "-3"], "argument --universe: '-3': expected a whole number of at least 1"),
    # refused only when its turn came, after every frame count of the sources before it
    (["--descriptors", "given", "foo"], "argument --descriptors: invalid choice: 'foo'"),
])
def test_an_argument_it_cannot_run_is_refused_when_parsed(tmp_path, capsys, args, message):
    path = tmp_path / "records.json"
    argv = [a for a in _args(path) if a not in ("--descriptors", "given")] + args
    with pytest.raises(SystemExit) as exc:
        _bench().main(argv)
    assert exc.value.code == 2
    out, err = capsys.readouterr()
    assert message in err and "Traceback" not in err
    assert out == "" and not path.exists()
