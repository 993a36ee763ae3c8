"""Mutated input files for the fuzz tests of the readers of user files.

Each fuzz test starts from a small valid file and damages it: cut it short, flip a byte,
replace a field with a hostile value (negative, huge, NaN, inf, empty, non-ASCII, of the
wrong type), drop, repeat or swap lines; in a JSON document delete a key, change a value's
type, shorten or lengthen a list. The reader must then return a result or raise
:class:`~pipeline.errors.InputError` whose message names the file; any other exception, or a
reader that takes longer than :data:`SLOW_S`, fails the test.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import re
import signal

from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

from pipeline.errors import InputError

#: examples per fuzz test: each test stays within a few seconds (``FUZZ_EXAMPLES=5000 pytest
#: --hypothesis-profile explore ...`` searches further)
FUZZ = settings(max_examples=int(os.environ.get("FUZZ_EXAMPLES", "80")), deadline=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much,
                                       HealthCheck.function_scoped_fixture,
                                       HealthCheck.data_too_large])

#: longest one reading may take (seconds) before the test calls it a hang
SLOW_S = 10

HOSTILE_TOKENS = [
    "", " ", "0", "-0", "-1", "1", "2", "3", "1.5", "-2.5", "1e309", "-1e309", "1e-320", "nan",
    "NaN", "inf", "-inf", "Infinity", "99999999999999999999", "2147483648", "4294967296",
    "-2147483649", "0x10", "1_0", "+1", "01", "1e3", "\u0661", "\u00e9", "\u00a0", "\x00",
    "\ufeff", '"', "'", ",", "#", "\t", "a", "None", "true", "[]", "1,2", "1 2", "\U0001f600",
]

HOSTILE_JSON = [
    None, True, False, 0, -1, 1, 2, 1.5, -0.5, 1e308, -1e308, 5e-324, 2**31, 2**63, 10**30,
    "", "x", "0", "1", "\u00e9", "\x00", "tcp/127.0.0.1:0", "tcp/127.0.0.1:7001", [], {},
    [0], [1, 2], [[0, 1]], {"a": 1}, float("nan"), float("inf"), float("-inf"),
]

_SEP = re.compile(r"([,;\s]+)")


@st.composite
def text_mutant(draw, valid: str, tokens=HOSTILE_TOKENS, max_ops: int = 3) -> str:
    """``valid`` with one to ``max_ops`` damages."""
    text = valid
    for _ in range(draw(st.integers(1, max_ops))):
        op = draw(st.sampled_from(["token", "token", "token", "truncate", "drop_line",
                                   "repeat_line", "swap_lines", "insert", "empty_field"]))
        lines = text.split("\n")
        if op in ("token", "empty_field"):
            parts = _SEP.split(text)
            idx = [k for k in range(0, len(parts), 2) if parts[k]]
            if not idx:
                continue
            k = draw(st.sampled_from(idx))
            parts[k] = "" if op == "empty_field" else draw(
                st.one_of(st.sampled_from(tokens), st.text(max_size=3)))
            text = "".join(parts)
        elif op == "truncate":
            text = text[:draw(st.integers(0, max(len(text) - 1, 0)))]
        elif op == "drop_line" and len(lines) > 1:
            del lines[draw(st.integers(0, len(lines) - 1))]
            text = "\n".join(lines)
        elif op == "repeat_line":
            k = draw(st.integers(0, len(lines) - 1))
            lines.insert(k, lines[k])
            text = "\n".join(lines)
        elif op == "swap_lines" and len(lines) > 1:
            a, b = draw(st.integers(0, len(lines) - 1)), draw(st.integers(0, len(lines) - 1))
            lines[a], lines[b] = lines[b], lines[a]
            text = "\n".join(lines)
        elif op == "insert":
            k = draw(st.integers(0, len(text)))
            text = text[:k] + draw(st.sampled_from(tokens + [" ", ",", "\n", "\r"])) + text[k:]
    return text


@st.composite
def bytes_mutant(draw, valid: bytes, max_ops: int = 3) -> bytes:
    """``valid`` cut short, with bytes flipped or overwritten."""
    data = bytearray(valid)
    for _ in range(draw(st.integers(1, max_ops))):
        op = draw(st.sampled_from(["flip", "flip", "set", "truncate", "insert"]))
        if not data:
            break
        k = draw(st.integers(0, len(data) - 1))
        if op == "flip":
            data[k] ^= 1 << draw(st.integers(0, 7))
        elif op == "set":
            data[k] = draw(st.sampled_from([0, 0xFF, 0x7F, 0x80, ord("-"), ord("9")]))
        elif op == "truncate":
            del data[k:]
        else:
            data[k:k] = draw(st.binary(min_size=1, max_size=4))
    return bytes(data)


def _paths(doc, at=()):
    yield at
    if isinstance(doc, dict):
        for k, v in doc.items():
            yield from _paths(v, at + (k,))
    elif isinstance(doc, list):
        for k, v in enumerate(doc):
            yield from _paths(v, at + (k,))


def _get(doc, path):
    for k in path:
        doc = doc[k]
    return doc


@st.composite
def json_mutant(draw, valid, values=HOSTILE_JSON, max_ops: int = 2):
    """A deep copy of the JSON document ``valid`` with one to ``max_ops`` damages."""
    doc = json.loads(json.dumps(valid))
    for _ in range(draw(st.integers(1, max_ops))):
        paths = [p for p in _paths(doc) if p]
        if not paths:
            break
        path = draw(st.sampled_from(paths))
        parent, key = _get(doc, path[:-1]), path[-1]
        op = draw(st.sampled_from(["value", "value", "value", "delete", "wrap", "extra",
                                   "repeat"]))
        if op == "value":
            parent[key] = draw(st.sampled_from(values))
        elif op == "delete":
            del parent[key]
        elif op == "wrap":
            parent[key] = [parent[key]]
        elif op == "extra" and isinstance(parent, dict):
            parent[draw(st.sampled_from(["extra", "", "\u00e9"]))] = 1
        elif op == "repeat" and isinstance(parent, list):
            parent.insert(key, json.loads(json.dumps(parent[key])))
    return doc


@contextlib.contextmanager
def no_hang(what: str, seconds: int = SLOW_S):
    """Fail when the body runs longer than ``seconds`` (a reader that hangs on bad input)."""
    def late(signum, frame):
        raise AssertionError(f"{what} still running after {seconds} s")

    old = signal.signal(signal.SIGALRM, late)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def read_or_refuse(read, *names: str):
    """``read()``'s result, or None when it raised :class:`InputError` whose message holds
    each of ``names`` (e.g. the file's name); any other exception propagates."""
    with no_hang(getattr(read, "__name__", "reader")):
        try:
            return read()
        except InputError as exc:
            msg = str(exc)
            assert msg.strip(), "empty InputError message"
            for n in names:
                assert n in msg, f"{n!r} not in {msg!r}"
            return None


def finite(*values) -> bool:
    """Every value is a finite number."""
    return all(math.isfinite(float(v)) for v in values)
