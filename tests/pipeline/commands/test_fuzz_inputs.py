"""Fuzzed input files: every malformed input gets a clear error, never a traceback.

``resolve`` (links csv, comm-graph csv, fault flags) is driven through the command line
(:func:`pipeline.__main__.main`): it must exit with 0, or with 2 and an ``error:`` line that
names what was wrong. ``run-images`` graph files are fuzzed through
:func:`pipeline.commgraph.comm_graph`, which must return valid edges or raise ``InputError``.
Inputs are mostly CSV-shaped text built from hostile tokens (negative, huge, fractional,
non-numeric, empty, non-ASCII), plus raw bytes.
"""

import tempfile
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pipeline.__main__ import main
from pipeline.commgraph import comm_graph
from pipeline.errors import InputError

FUZZ = settings(max_examples=400, deadline=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much,
                                       HealthCheck.function_scoped_fixture])

TOKENS = st.one_of(
    st.integers(-3, 9).map(str),
    st.sampled_from(["", " ", "0", "1", "2", "-0", "+1", "01", "1.0", "1.5", "1e3", "nan", "inf",
                     "-inf", "0x1", "99999999999999999999", "2147483648", "cam_i", "cam_j",
                     "feat_i", "quality", "a.jpg", "b.jpg", "é", "\u00a0", "#", '"1"', "1 2",
                     "True", "None", "\x00", "1;2"]),
    st.text(max_size=4),
)


@st.composite
def csv_text(draw, max_cols=7):
    rows = draw(st.lists(st.lists(TOKENS, max_size=max_cols), max_size=8))
    sep = draw(st.sampled_from([",", ", ", ";", "\t", ",,"]))
    eol = draw(st.sampled_from(["\n", "\r\n", "\r"]))
    return eol.join(sep.join(r) for r in rows) + draw(st.sampled_from(["", eol]))


FILE_CONTENT = st.one_of(csv_text().map(lambda s: s.encode("utf-8", "surrogatepass")),
                         st.binary(max_size=64))

VALID_LINKS = b"0,0,1,0\n0,1,2,0\n1,0,2,1\n1,1,2,0\n"


def run_cli(tmp: Path, argv: list[str], capsys) -> None:
    """Run the CLI; a failure must be exit code 2 with a one-line ``error:`` message."""
    capsys.readouterr()
    rc = main(argv)
    err = capsys.readouterr().err
    assert rc in (0, 2), (rc, err)
    if rc == 2:
        assert err.startswith("error: ") and "Traceback" not in err, err
        assert len(err.strip()) > len("error: ")


def write(tmp: Path, name: str, content: bytes) -> str:
    path = tmp / name
    path.write_bytes(content)
    return str(path)


@FUZZ
@given(FILE_CONTENT)
def test_resolve_links_file(capsys, content):
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        run_cli(tmp, ["resolve", "--links", write(tmp, "in.csv", content),
                      "--out", str(tmp / "out.csv")], capsys)


@FUZZ
@given(FILE_CONTENT)
def test_resolve_comm_graph_file(capsys, content):
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        run_cli(tmp, ["resolve", "--links", write(tmp, "in.csv", VALID_LINKS),
                      "--comm-graph", write(tmp, "g.csv", content),
                      "--out", str(tmp / "out.csv")], capsys)


@settings(max_examples=100, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(st.lists(st.text(max_size=8), max_size=3), st.text(max_size=6), st.text(max_size=4),
       st.booleans())
def test_resolve_fault_flags(capsys, crashes, drop, seed, switching):
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        argv = ["resolve", "--links", write(tmp, "in.csv", VALID_LINKS),
                "--out", str(tmp / "out.csv"), f"--drop-prob={drop}", f"--fault-seed={seed}"]
        argv += [f"--crash={c}" for c in crashes] + (["--switching-topology"] * switching)
        run_cli(tmp, argv, capsys)


NAMES = ["a.jpg", "b.jpg", "c.jpg", "d.jpg"]


@FUZZ
@given(FILE_CONTENT)
def test_run_images_graph_file(content):
    with tempfile.TemporaryDirectory() as d:
        path = write(Path(d), "graph.txt", content)
        try:
            e = comm_graph(path, NAMES)
        except InputError as exc:
            assert str(exc)
            return
        assert e.ndim == 2 and e.shape[1] == 2 and len(e) >= 1
        assert (e[:, 0] < e[:, 1]).all() and e.min() >= 0 and e.max() < len(NAMES)
        assert len(np.unique(e, axis=0)) == len(e)
