"""The command line: cheap top-level help, every command's own help, a run that imports only
what it uses (checked in fresh interpreters through ``sys.modules``, never by timing); the
program names itself, has --version, --quiet, and the licence file matches the package
metadata."""

from __future__ import annotations

import ast
import json
import os
import subprocess
import sys
import textwrap
import tomllib
from pathlib import Path

import pytest

from pipeline import __version__
from pipeline.__main__ import COMMANDS, _requested_command, build_parser, configure_logging, main
from pipeline.progress import StageTimer

ROOT = Path(__file__).resolve().parents[2]
HEAVY = ("cv2", "scipy", "pycolmap", "rerun")


def _imported_after(code: str, env: dict | None = None) -> set[str]:
    """Names in ``sys.modules`` (modules and their top-level packages) after running ``code``
    in a new interpreter."""
    probe = (f"import sys\n{code}\n"
             "import json\nprint(json.dumps(sorted(set(sys.modules)\n"
             "                                  | {m.split('.')[0] for m in sys.modules})))")
    out = subprocess.run([sys.executable, "-c", probe], cwd=ROOT, capture_output=True,
                         text=True, check=True, env={**os.environ, **(env or {})})
    return set(json.loads(out.stdout.strip().splitlines()[-1]))


def test_top_level_help_imports_no_heavy_library():
    code = ("from pipeline.__main__ import main\n"
            "try:\n    main(['--help'])\nexcept SystemExit as e:\n    assert e.code == 0\n")
    loaded = _imported_after(code)
    assert "pipeline" in loaded
    assert not loaded & set(HEAVY), sorted(loaded & set(HEAVY))


def test_python_dash_m_help_lists_every_command():
    out = subprocess.run([sys.executable, "-m", "pipeline", "--help"], cwd=ROOT,
                         capture_output=True, text=True, check=True).stdout
    for name in COMMANDS:
        assert name in out


@pytest.mark.parametrize("command", list(COMMANDS))
def test_each_command_has_its_own_help(command, capsys):
    with pytest.raises(SystemExit) as exc:
        main([command, "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert f"formation-match {command}" in out
    assert "--" in out.split("options:", 1)[1].replace("-h, --help", "")


@pytest.mark.parametrize("argv, command", [
    (["run-formation", "--seed", "3"], "run-formation"),
    (["--help", "run-formation"], None),
    (["bogus"], None),
    ([], None),
])
def test_requested_command(argv, command):
    assert _requested_command(argv) == command


def test_unknown_command_is_an_argparse_error(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["bogus"])
    assert exc.value.code == 2
    assert "invalid choice: 'bogus'" in capsys.readouterr().err


def test_run_without_rerun_or_fusion_imports_neither(tmp_path):
    code = ("from pipeline.runs.formation import FormationConfig, run_formation\n"
            f"run_formation(FormationConfig(formation='a', size=(160, 120), max_features=200, "
            f"fusion=False, rerun=False, out={str(tmp_path / 'run')!r}))\n"
            "assert 'pipeline.fusion.voting' not in sys.modules\n")
    loaded = _imported_after(code, {"FORMATION_MATCH_CACHE": str(tmp_path / "cache")})
    assert "pycolmap" in loaded  # the run did triangulate
    assert "rerun" not in loaded
    assert (tmp_path / "run" / "report.json").is_file()


#: optional libraries that the default run-formation never needs (team transport, plots,
#: hloc files, tests, progress bars off a terminal, pandas that Rerun would use if present)
NEVER_ON_THE_DEFAULT_PATH = ("zenoh", "matplotlib", "h5py", "hypothesis", "pytest", "tqdm",
                             "pandas", "scipy.stats", "pyarrow.compute", "pipeline.team.assemble",
                             "pipeline.transport.zenoh", "pipeline.runs.images")
#: the modules of the default run-formation, in stage order
DEFAULT_RUN_MODULES = ("pipeline.__main__", "pipeline.commands.run_formation", "pipeline.stages",
                       "data_synth", "pipeline.matching.features", "pipeline.matching.pairs",
                       "pipeline.consistency", "pipeline.fusion.landmarks", "pipeline.evaluation.links",
                       "pipeline.evaluation.metrics", "pipeline.evaluation.report", "pipeline.evaluation.oracle")


def test_default_run_modules_load_no_optional_library():
    loaded = _imported_after("\n".join(f"import {m}" for m in DEFAULT_RUN_MODULES))
    assert set(DEFAULT_RUN_MODULES) <= loaded
    unwanted = set(NEVER_ON_THE_DEFAULT_PATH) | {"rerun", "pyarrow", "pycolmap"}
    # pycolmap and Rerun are loaded by the stages that use them (triangulation, write), so
    # that the peak memory of the earlier stages does not hold them
    assert not loaded & unwanted, sorted(loaded & unwanted)


@pytest.mark.parametrize("rerun", [True, False])
def test_default_command_imports_only_what_it_uses(rerun, tmp_path):
    argv = ["run-formation", "--formation", "a", "--size", "160x120", "--max-features", "200",
            "--out", str(tmp_path / "run")] + ([] if rerun else ["--no-rerun"])
    code = ("from pipeline.__main__ import main\n"
            f"assert main({argv!r}) in (0, 3)\n")
    loaded = _imported_after(code, {"FORMATION_MATCH_CACHE": str(tmp_path / "cache")})
    assert {"pipeline.fusion.voting", "pycolmap"} <= loaded  # fusion ran, pycolmap checked
    unwanted = set(NEVER_ON_THE_DEFAULT_PATH) | (set() if rerun else {"rerun", "pyarrow", "PIL"})
    assert not loaded & unwanted, sorted(loaded & unwanted)
    assert ("rerun" in loaded) == rerun == (tmp_path / "run" / "recording.rrd").is_file()


def test_program_exit_keeps_output_and_exit_code(tmp_path):
    """Run as a program, the process ends without the interpreter's teardown: what it printed
    to a pipe is all there, and the exit code is the command's (0, then 2 for bad input)."""
    env = {**os.environ, "FORMATION_MATCH_CACHE": str(tmp_path / "cache")}
    ok = subprocess.run([sys.executable, "-m", "pipeline", "match-formation", "--formation", "a",
                         "--size", "160x120", "--max-features", "200"],
                        cwd=ROOT, capture_output=True, text=True, env=env)
    assert ok.returncode == 0, ok.stderr
    assert ok.stdout.rstrip().endswith("|")  # the table's last row, flushed before the exit
    assert "time evaluate [s]" in ok.stdout
    assert "[evaluate] done" in ok.stderr
    bad = subprocess.run([sys.executable, "-m", "pipeline", "match-formation", "--formation",
                          "zz"], cwd=ROOT, capture_output=True, text=True, env=env)
    assert bad.returncode == 2
    assert "--formation 'zz'" in bad.stderr


def test_program_under_a_profiler_exits_normally(tmp_path):
    """A profiler writes its data after the program's main returns: the early exit must not
    cut it off."""
    stats = tmp_path / "run.prof"
    out = subprocess.run([sys.executable, "-m", "cProfile", "-o", str(stats), "-m", "pipeline",
                          "match-formation", "--formation", "zz"], cwd=ROOT,
                         capture_output=True, text=True)
    assert "--formation 'zz'" in out.stderr  # the command ran (cProfile swallows its exit code)
    assert stats.is_file() and stats.stat().st_size > 0


def test_fusion_does_not_import_scipy_stats():
    loaded = _imported_after("import pipeline.fusion.landmarks")
    assert "pipeline.fusion.voting" in loaded
    assert "scipy.stats" not in loaded


def test_help_names_the_program(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    assert capsys.readouterr().out.startswith("usage: formation-match")


@pytest.mark.parametrize("argv", [["--version"], ["run-formation", "--version"],
                                  ["resolve", "--version"]])
def test_version(capsys, argv):
    """``--version`` before or after the command (after it, it was an unrecognized argument)."""
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"formation-match {__version__}"


def test_every_command_takes_quiet():
    parser = build_parser()
    for argv in (["clean-db", "x.db", "--out", "y.db", "--quiet"],
                 ["run-images", "DIR", "--graph", "complete", "-q"]):
        assert parser.parse_args(argv).quiet


def test_quiet_hides_stage_lines_and_keeps_warnings(capsys):
    try:
        configure_logging(quiet=False)
        with StageTimer().stage("features", "sift"):
            pass
        err = capsys.readouterr().err
        assert "[features] sift ..." in err and "done in" in err
        configure_logging(quiet=True)
        timer = StageTimer()
        with timer.stage("features"):
            timer.warn("few images registered")
        err = capsys.readouterr().err
        assert "[features]" not in err and "few images registered" in err
    finally:
        configure_logging(quiet=False)


def test_licence_file_matches_pyproject():
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert meta["license"] == "MIT"
    assert "LICENSE" in meta.get("license-files", [])
    text = (ROOT / "LICENSE").read_text()
    assert text.startswith("MIT License") and "WITHOUT WARRANTY OF ANY KIND" in text


def _imports_of(path: Path) -> set[str]:
    """Top-level names of every module ``path`` imports, at any depth of its code."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names.update(a.name.split(".")[0] for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    return names


def test_matplotlib_is_an_extra_of_the_benches_only():
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert not [d for d in meta["dependencies"] if d.startswith("matplotlib")]
    assert [d for d in meta["optional-dependencies"]["bench"] if d.startswith("matplotlib")]
    users = sorted(str(p.relative_to(ROOT)) for pkg in ("pipeline", "viz", "data_synth")
                   for p in (ROOT / pkg).rglob("*.py") if "matplotlib" in _imports_of(p))
    assert users == []
    assert "matplotlib" in _imports_of(ROOT / "bench" / "voting_fig23.py")  # the scan sees it


# ----------------------------------------------------------------------- Ctrl-C, however early

def test_ctrl_c_while_the_command_module_loads_is_one_line_exit_130(monkeypatch, capsys):
    import pipeline.__main__ as entry

    def interrupted(commands):
        raise KeyboardInterrupt

    monkeypatch.setattr(entry, "build_parser", interrupted)
    assert main(["resolve", "--links", "x", "--out", "y"]) == 130
    err = capsys.readouterr().err
    assert err == "interrupted: resolve stopped, nothing was written or replaced\n"


def test_ctrl_c_after_the_outputs_are_in_place_does_not_say_nothing_was_written(
        tmp_path, monkeypatch, capsys):
    """A Ctrl-C while the summary is printed, after OUT.csv and --report were put in place,
    said 'nothing was written or replaced' although both had been (re)written: it now names
    them as complete; a later command's interrupt does not inherit them."""
    import pipeline.outcome

    links, out, report = tmp_path / "in.csv", tmp_path / "out.csv", tmp_path / "r.json"
    links.write_text("0,0,1,0\n1,0,2,0\n0,1,2,0\n")

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(pipeline.outcome, "exit_status", interrupted)  # after the outputs
    assert main(["resolve", "--links", str(links), "--out", str(out), "--report",
                 str(report)]) == 130
    assert out.is_file() and report.is_file()
    err = capsys.readouterr().err
    assert "nothing was written" not in err
    assert err == (f"interrupted: resolve stopped; already in place, complete: {str(out)!r}, "
                   f"{str(report)!r}\n")
    import pipeline.__main__ as entry

    monkeypatch.setattr(entry, "build_parser", interrupted)
    assert main(["resolve", "--links", "x", "--out", "y"]) == 130
    assert capsys.readouterr().err == ("interrupted: resolve stopped, nothing was written or "
                                       "replaced\n")


def test_ctrl_c_while_a_cxx_extension_loads_is_not_an_import_error(monkeypatch, capsys):
    """pybind11 turns a KeyboardInterrupt during a module's initialisation into an
    ImportError, which pycolmap turns into 'Cannot import the C++ backend'."""
    import importlib

    import pipeline.__main__ as entry

    real = importlib.import_module

    def interrupted_load(name, *a):
        if name == "pipeline.commands.resolve":
            try:
                try:
                    raise KeyboardInterrupt
                except KeyboardInterrupt as exc:
                    raise ImportError("initialization failed") from exc
            except ImportError as exc:
                raise RuntimeError("Cannot import the C++ backend pycolmap._core.") from exc
        return real(name, *a)

    monkeypatch.setattr(entry.importlib, "import_module", interrupted_load)
    assert main(["resolve", "--links", "x", "--out", "y"]) == 130
    err = capsys.readouterr().err
    assert err.startswith("interrupted: resolve stopped") and "C++" not in err


def test_ctrl_c_that_a_library_drops_while_it_loads_is_still_an_interrupt():
    """NumPy's C code, interrupted while it imports ``datetime``, drops the KeyboardInterrupt
    and raises ``ImportError: PyCapsule_Import could not import module "datetime"`` with no
    link to it (seen in the real-process test below, once): the program records
    that a Ctrl-C arrived, so this too ends with one line and exit 130, not a traceback."""
    code = textwrap.dedent("""
        import signal, sys
        from pipeline.errors import exit_quietly_on_interrupt, run_interruptibly
        exit_quietly_on_interrupt("prog")

        def load():
            dropped = False
            try:
                signal.raise_signal(signal.SIGINT)
            except KeyboardInterrupt:
                dropped = True  # what the C code does with it
            if dropped:
                raise ImportError('PyCapsule_Import could not import module "datetime"')
            return 0

        sys.exit(run_interruptibly("prog", load))
    """)
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60)
    assert (done.returncode, done.stderr) == (
        130, "interrupted: prog stopped, nothing was written or replaced\n")


@pytest.mark.parametrize("delay", [0.1, 0.25, 0.5])
def test_ctrl_c_in_the_first_second_ends_with_130_and_no_traceback(tmp_path, delay):
    """A real process, interrupted while Python loads NumPy, SciPy and the command: ``delay``
    seconds after the interpreter's own start (which runs before any of the program's code: a
    Ctrl-C there is Python's, e.g. "Fatal Python error: init_import_site" on a loaded
    machine, so the process says when it is past it, and the clock starts then)."""
    import signal
    import time

    src = tmp_path / "in.csv"
    src.write_text("0,0,1,0\n1,0,2,0\n0,1,2,0\n")
    argv = ["pipeline", "resolve", "--links", str(src), "--out", str(tmp_path / "o.csv")]
    start = ("import runpy, sys\n"
             f"sys.argv = {argv!r}\n"
             "sys.stdout.write('started\\n'); sys.stdout.flush()\n"
             "runpy.run_module('pipeline', run_name='__main__', alter_sys=True)\n")
    proc = subprocess.Popen([sys.executable, "-c", start], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=ROOT)
    assert proc.stdout.readline() == "started\n"
    time.sleep(delay)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert "Traceback" not in err and "C++" not in err, err
    assert proc.returncode in (0, 130), (proc.returncode, err)  # 0: it was done already
    if proc.returncode == 130:
        assert err.strip().splitlines()[-1].startswith("interrupted:")
        assert not (tmp_path / "o.csv").exists()



def test_a_closed_stdout_pipe_ends_the_command_quietly(tmp_path):
    """``formation-match match-formation … | head -3``: the reader stops reading while the
    command still prints; the command ends quietly with exit code 0, no 'error: Broken pipe'.
    (Unbuffered stdout makes every print meet the closed pipe, whatever the output's size.)"""
    env = {**os.environ, "FORMATION_MATCH_CACHE": str(tmp_path / "cache"),
           "PYTHONUNBUFFERED": "1"}
    read, write = os.pipe()
    os.close(read)  # the reader has gone before the first line
    try:
        out = subprocess.run([sys.executable, "-m", "pipeline", "match-formation", "--formation",
                              "a", "--size", "160x120", "--max-features", "200", "-q"],
                             cwd=ROOT, stdout=write, stderr=subprocess.PIPE, text=True, env=env)
    finally:
        os.close(write)
    assert out.stderr == ""
    assert out.returncode == 0


def test_a_stage_past_its_bound_of_rounds_is_one_line_exit_2(tmp_path, monkeypatch, capsys):
    """Two robots that read one link otherwise (quality 0.9 and 0.8) with the ends' comparison
    taken away: sync runs past its bound of Borůvka rounds, which each robot command ended with
    a traceback (exit 1); it is one line naming the robot and the bound, exit 2."""
    import threading

    import pipeline.team.robot as teamrobot
    from pipeline.__main__ import _run
    from pipeline.team.launcher import free_ports

    monkeypatch.setattr(teamrobot, "check_shared_links", lambda *a, **k: None)
    head = "cam_i,feat_i,cam_j,feat_j,quality\n"
    (tmp_path / "r0.csv").write_text(head + "0,0,1,0,0.9\n")
    (tmp_path / "r1.csv").write_text(head + "0,0,1,0,0.8\n")
    team = tmp_path / "TEAM.json"
    team.write_text(json.dumps({
        "version": 1, "name": "stalled", "comm_edges": [[0, 1]],
        "robots": [{"id": i, "endpoint": f"tcp/127.0.0.1:{p}"}
                   for i, p in enumerate(free_ports(2))],
        "data": {"kind": "links", "links": [str(tmp_path / "r0.csv"), str(tmp_path / "r1.csv")],
                 "features_per_camera": [1, 1]},
        "options": {"resolution": "sync", "start_timeout_s": 20.0}}))
    codes = [None, None]

    def robot(i):
        codes[i] = _run(["robot", "--team", str(team), "--id", str(i)], "robot")

    threads = [threading.Thread(target=robot, args=(i,)) for i in (0, 1)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    err = capsys.readouterr().err
    assert codes == [2, 2] and "Traceback" not in err, err
    lines = sorted(ln for ln in err.splitlines() if ln.startswith("error:"))
    assert [ln.split(",")[0] for ln in lines] == [
        f"error: robot {i}: sync did not end within 2 Borůvka rounds" for i in (0, 1)]
    assert all(ln.endswith("or the stage has a defect") for ln in lines), lines
