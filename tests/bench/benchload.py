"""Load a bench script, ``bench/NAME.py``, as a module (the benches are scripts, not a package)."""

import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
#: every bench script's name
BENCHES = sorted(p.stem for p in (ROOT / "bench").glob("*.py"))


def load_bench(name: str):
    """``bench/NAME.py`` imported afresh as ``bench_NAME``; ``bench/`` goes on ``sys.path``
    (a bench may import another, as ``team_moves`` imports ``multiway``)."""
    if str(ROOT / "bench") not in sys.path:
        sys.path.insert(0, str(ROOT / "bench"))
    spec = importlib.util.spec_from_file_location(f"bench_{name}", ROOT / "bench" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


class _Parsed(Exception):
    pass


def default_options(monkeypatch, name: str):
    """The options ``bench/NAME.py`` parses with no argument, stopped right after parsing
    (no work done): its argparse Namespace."""
    import argparse

    parse = argparse.ArgumentParser.parse_args

    def parsed(self, args=None, namespace=None):
        raise _Parsed(parse(self, args, namespace))
    monkeypatch.setattr(argparse.ArgumentParser, "parse_args", parsed)
    main = load_bench(name).main
    try:
        getattr(main, "__wrapped__", main)([])
    except _Parsed as exc:
        return exc.args[0]
    raise AssertionError(f"bench/{name}.py did not parse its arguments")


def shadowing_package(folder: Path, name: str, body: str) -> Path:
    """``folder`` holding a package ``name`` whose ``__init__.py`` is ``body``: put first on a
    bench's ``PYTHONPATH``, it stands in for the real one."""
    (folder / name).mkdir()
    (folder / name / "__init__.py").write_text(body)
    return folder


#: what a bench's ``--out`` folder holds before a run that must leave it as it was
PREVIOUS = '{"previous": true}'


def previous_results(tmp_path: Path) -> Path:
    """A bench's ``--out`` folder holding a previous ``results.json`` (:data:`PREVIOUS`)."""
    out = tmp_path / "bench"
    out.mkdir()
    (out / "results.json").write_text(PREVIOUS)
    return out


def refused(main, argv: list[str], out: Path, capsys) -> str:
    """``main(argv)`` is refused: exit status 2 (returned, or argparse's ``SystemExit``), no
    traceback, and ``out`` as :func:`previous_results` made it; returns what it printed on
    stderr."""
    try:  # argparse's refusals exit; an InputError is printed and returned (one_line_errors)
        code = main(argv)
    except SystemExit as exc:
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    assert [p.name for p in out.iterdir()] == ["results.json"]
    assert (out / "results.json").read_text() == PREVIOUS
    return err
