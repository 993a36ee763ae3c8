"""Fault flags: parsing, validation, network options and the report section."""

import argparse

import numpy as np
import pytest

from pipeline.consistency import resolve_conflicts
from pipeline.errors import InputError
from pipeline.faults import (
    FaultConfig,
    add_fault_arguments,
    fault_report,
    faults_from_args,
    parse_crash,
)
from pipeline.types import Links


def parse(argv):
    p = argparse.ArgumentParser()
    add_fault_arguments(p)
    return faults_from_args(p.parse_args(argv))


def test_defaults_are_fault_free():
    cfg = parse([])
    assert cfg == FaultConfig() and not cfg.any
    assert cfg.network_options([[0, 1]], 2) is None


def test_flags_parse():
    cfg = parse(["--drop-prob", "0.3", "--crash", "2@15", "--crash", " 0 @ 4 ",
                 "--switching-topology", "--fault-seed", "7"])
    assert cfg.drop_prob == 0.3 and cfg.crash == ((2, 15), (0, 4))
    assert cfg.switching_topology and cfg.seed == 7 and cfg.any
    opts = cfg.network_options([[0, 1], [1, 2]], 3)
    assert opts.drop_probability == 0.3 and opts.crash_at == {2: 15, 0: 4} and opts.seed == 7
    edges = np.asarray(opts.topology(0))
    assert edges.ndim == 2 and edges.shape[1] == 2
    assert cfg.as_dict()["crash"] == ["2@15", "0@4"]


@pytest.mark.parametrize("text", ["2", "2@", "@3", "a@3", "2@x", "-1@3", "2@-3", "2@3@4",
                                  "2.5@3", "", "2 3"])
def test_bad_crash_syntax_is_an_input_error(text):
    with pytest.raises(InputError, match="ROBOT@ROUND"):
        parse_crash(text)


@pytest.mark.parametrize("argv, match", [
    (["--drop-prob", "1"], "must be in"), (["--drop-prob", "-0.1"], "must be in"),
    (["--drop-prob", "half"], "not a number"), (["--drop-prob", "nan"], "must be in"),
    (["--crash", "1@2", "--crash", "1@5"], "more than once"),
    (["--fault-seed", "x"], "not an integer"),
])
def test_bad_values_are_input_errors(argv, match):
    with pytest.raises(InputError, match=match):
        parse(argv)


def test_crash_of_an_unknown_robot_names_it():
    cfg = parse(["--crash", "9@3"])
    with pytest.raises(InputError, match=r"robot 9 does not exist; robots are 0\.\.3"):
        cfg.network_options([[0, 1]], 4)


def test_report_section_records_injection_and_effect():
    links = Links([0, 0, 1, 2], [0, 0, 0, 0], [3, 1, 2, 3], [1, 0, 0, 0])  # paper Fig. 1
    cfg = FaultConfig(drop_prob=0.2, crash=((3, 2),), seed=1)
    res = resolve_conflicts([1, 1, 1, 2], None, links, cfg.network_options([[0, 1]], 4))
    base = resolve_conflicts([1, 1, 1, 2], None, links)
    rep = fault_report(cfg, res, base)
    assert rep["injected"]["crash"] == ["3@2"] and rep["protocol"] == "reliable"
    assert rep["crashed"] == {"3": 2} and rep["robots_lost"] == {"3": [0, 2]}
    assert rep["links_cut_robot_lost"] == 2
    assert rep["extra_rounds"] > 0 and rep["extra_messages"] > 0
    assert rep["extra_rounds"] == rep["rounds"] - rep["fault_free_rounds"]
