"""The registry of resolution rules: every name is read from it, and a toy rule registered by a
module of its own runs end to end through ``resolve`` on both transports."""

import json
import os
from pathlib import Path

import numpy as np
import pytest

from pipeline.__main__ import build_parser, main
from pipeline.consistency import evidence, robot
from pipeline.consistency.rules import RULES, get_rule, register, rule_names, unregister
from pipeline.errors import InputError

HERE = Path(__file__).resolve().parent
# Fig. 1 of the paper (one conflictive set, four links) and one link outside any conflict
LINKS = "cam_i,feat_i,cam_j,feat_j\n0,0,3,1\n0,0,1,0\n1,0,2,0\n3,0,2,0\n0,1,1,1\n"


def _resolve_fig1(rule: str, transport: str, tmp_path, capsys):
    """``resolve`` on :data:`LINKS` with ``rule`` over ``transport``: what it printed, its
    report and every row's status."""
    src, out, report = tmp_path / "in.csv", tmp_path / "out.csv", tmp_path / "r.json"
    src.write_text(LINKS)
    assert main(["resolve", "--links", str(src), "--out", str(out), "--resolution", rule,
                 "--transport", transport, "--report", str(report)]) == 0
    rows = out.read_text().splitlines()[1:]
    return (capsys.readouterr().out, json.loads(report.read_text()),
            [r.split(",")[4] for r in rows])


def test_the_rules_codes_are_the_robots_own():
    from pipeline.consistency import sync

    assert get_rule("paper").cases == {robot.CASE_B: "b", robot.CASE_C: "c"}
    assert get_rule("evidence").cases == {evidence.CASE_EVIDENCE: "evidence"}
    assert get_rule("sync").cases == {sync.CASE_SYNC: "sync"}


def test_every_hook_of_a_rule_without_detection_loads():
    rule = get_rule("sync")
    assert not rule.detection
    for hook in ("stage", "alone", "equip"):
        assert callable(rule.hook(hook)), hook


@pytest.mark.parametrize("transport", ["sim", "zenoh"])
def test_the_sync_rule_runs_through_resolve_on_both_transports(transport, tmp_path, capsys):
    # Fig. 1 (global ids 0,1 | 2,3 | 4 | 5,6): equal weights and no triangle, so the greedy
    # merge takes the links in the order of their tie keys (keys.tie_key): (4,5), (2,4),
    # (0,6), (1,3); then (0,2) would join a cluster holding 6 to one holding 5, both of
    # camera 3: (0,0)-(1,0) is cut
    from pipeline.consistency.keys import tie_key

    assert np.argsort(tie_key([0, 0, 2, 4, 1], [6, 2, 4, 5, 3])).tolist() == [3, 2, 0, 4, 1]
    printed, s, statuses = _resolve_fig1("sync", transport, tmp_path, capsys)
    assert "deleted: 1 links by the multi-way matching" in printed
    assert s["resolution_method"] == "sync"
    assert s["deleted_by_case"] == {"b": 0, "c": 0, "sync": 1}
    assert s["after"]["conflictive_sets"] == 0
    assert statuses == ["kept", "deleted", "kept", "kept", "kept"]


@pytest.mark.parametrize("name, hooks", [
    ("paper", ("simulate", "batched", "start", "step", "done", "finish")),
    ("evidence", ("stage", "stage_batched", "alone", "equip")),
    ("sync", ("stage", "stage_batched", "alone", "equip"))])
def test_every_hook_of_a_registered_rule_loads(name, hooks):
    rule = get_rule(name)
    for hook in hooks:
        assert callable(rule.hook(hook)), hook


def test_an_unknown_rule_is_named_with_the_choices():
    with pytest.raises(InputError, match="resolution 'best': choose one of paper, evidence, sync"):
        get_rule("best")
    with pytest.raises(ValueError, match="already registered"):
        register(get_rule("paper"))


def test_command_line_choices_are_the_registry():
    parser = build_parser(["resolve", "run-formation", "run-landmarks"])
    sub = next(a for a in parser._actions if a.dest == "command")
    for command in ("resolve", "run-formation", "run-landmarks"):
        option = next(a for a in sub.choices[command]._actions if a.dest == "resolution")
        assert tuple(option.choices) == rule_names()


@pytest.fixture
def toy_rule(monkeypatch):
    """The toy rule registered here and, through FORMATION_MATCH_RULES, in robot processes."""
    monkeypatch.setenv("FORMATION_MATCH_RULES", "toy_rule")
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(
        [str(HERE), *filter(None, [os.environ.get("PYTHONPATH")])]))
    monkeypatch.syspath_prepend(str(HERE))
    import toy_rule

    if "toy" not in RULES:
        register(toy_rule.TOY)
    yield toy_rule.TOY
    unregister("toy")
    assert "toy" not in rule_names()


@pytest.mark.parametrize("transport", ["sim", "zenoh"])
def test_a_toy_rule_runs_end_to_end_through_resolve(toy_rule, transport, tmp_path, capsys):
    printed, s, statuses = _resolve_fig1("toy", transport, tmp_path, capsys)
    assert "deleted: 4 links by the toy rule" in printed
    assert s["resolution_method"] == "toy"
    assert s["deleted_by_case"] == {"b": 0, "c": 0, "toy": 4}
    assert s["before"]["conflictive_sets"] == 1 and s["after"]["conflictive_sets"] == 0
    assert statuses == ["deleted"] * 4 + ["kept"]


def test_a_toy_transport_runs_resolve(tmp_path, capsys):
    from types import SimpleNamespace

    from pipeline.runs.transports import TransportEntry, get_transport
    from pipeline.runs.transports import register as register_transport
    from pipeline.runs.transports import unregister as unregister_transport

    calls = []
    sim = get_transport("sim").load()

    def resolve(*args):
        calls.append(args)
        return sim.resolve(*args)

    register_transport(TransportEntry("loopback", "the simulator, counted",
                                      lambda: SimpleNamespace(resolve=resolve)))
    try:
        src = tmp_path / "in.csv"
        src.write_text(LINKS)
        for transport in ("sim", "loopback"):
            assert main(["resolve", "--links", str(src), "--out", str(tmp_path / f"{transport}.csv"),
                         "--resolution", "paper", "--transport", transport]) == 0
    finally:
        unregister_transport("loopback")
    assert len(calls) == 1
    assert (tmp_path / "sim.csv").read_text() == (tmp_path / "loopback.csv").read_text()
    with pytest.raises(SystemExit):
        main(["resolve", "--links", str(src), "--out", str(tmp_path / "x.csv"),
              "--transport", "loopback"])
    assert "invalid choice" in capsys.readouterr().err
