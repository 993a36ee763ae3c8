"""resolve, as a hostile user would run it: every case ends in one line on stderr and the
documented exit code, with nothing of the user's touched."""

import json
import os
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pipeline.__main__ import main

sys.path.insert(0, str(Path(__file__).parent))
sys.path.insert(0, str(Path(__file__).parents[1] / "consistency"))
from consistency_graphs import random_instance  # noqa: E402
from hostile import one_line_error, refused, run_capped  # noqa: E402

FIG1 = "cam_i,feat_i,cam_j,feat_j\n0,0,3,1\n0,0,1,0\n1,0,2,0\n3,0,2,0\n"


@pytest.fixture
def fig1(tmp_path):
    src = tmp_path / "in.csv"
    src.write_text(FIG1)
    return src




# ------------------------------------------------------------------------------ data loss

def test_report_onto_the_input_is_refused(fig1, tmp_path, capsys):
    assert main(["resolve", "--links", str(fig1), "--out", str(tmp_path / "o.csv"),
                 "--report", str(fig1)]) == 2
    one_line_error(capsys, "--report", "input file given as --links")
    assert fig1.read_text() == FIG1 and not (tmp_path / "o.csv").exists()


def test_out_onto_the_comm_graph_is_refused(fig1, tmp_path, capsys):
    graph = tmp_path / "g.csv"
    graph.write_text("0,1\n1,2\n2,3\n0,3\n")
    assert main(["resolve", "--links", str(fig1), "--comm-graph", str(graph),
                 "--out", str(graph), "--overwrite"]) == 2
    one_line_error(capsys, "--comm-graph")
    assert graph.read_text() == "0,1\n1,2\n2,3\n0,3\n"


def test_out_through_a_symlink_to_the_input_is_refused(fig1, tmp_path, capsys):
    (tmp_path / "alias.csv").symlink_to(fig1)
    assert main(["resolve", "--links", str(fig1), "--out", str(tmp_path / "alias.csv"),
                 "--overwrite"]) == 2
    one_line_error(capsys, "symbolic link")
    assert fig1.read_text() == FIG1 and (tmp_path / "alias.csv").is_symlink()


@pytest.mark.parametrize("special", ["fifo", "/dev/null"])
def test_special_files_are_never_replaced(fig1, tmp_path, capsys, special):
    target = tmp_path / "fifo" if special == "fifo" else Path(special)
    if special == "fifo":
        os.mkfifo(target)
    assert main(["resolve", "--links", str(fig1), "--out", str(target), "--overwrite"]) == 2
    one_line_error(capsys, "not a regular file")
    assert not target.is_file()


def test_existing_output_needs_overwrite(fig1, tmp_path, capsys):
    out = tmp_path / "o.csv"
    out.write_text("keep me")
    assert main(["resolve", "--links", str(fig1), "--out", str(out)]) == 2
    one_line_error(capsys, "already exists; pass --overwrite")
    assert out.read_text() == "keep me"
    assert main(["resolve", "--links", str(fig1), "--out", str(out), "--overwrite"]) == 0
    assert out.read_text().startswith("cam_i,feat_i,cam_j,feat_j,status")


def test_out_naming_a_folder_is_refused(fig1, tmp_path, capsys):
    assert main(["resolve", "--links", str(fig1), "--out", str(tmp_path)]) == 2
    one_line_error(capsys, "is a folder")


def test_read_only_location_is_aone_line_error(fig1, tmp_path, capsys, refuse_writes_in):
    refuse_writes_in(tmp_path)
    assert main(["resolve", "--links", str(fig1), "--out", str(tmp_path / "ro" / "o.csv")]) == 2
    one_line_error(capsys, "cannot write in")


def test_links_naming_a_folder_says_it_is_a_folder(tmp_path, capsys):
    assert main(["resolve", "--links", str(tmp_path), "--out", str(tmp_path / "o.csv")]) == 2
    one_line_error(capsys, "is a folder, not a file")


# ------------------------------------------------------------------ meaningless values

@pytest.mark.parametrize("flag,value,message", [
    ("--fault-seed", "-5", "--fault-seed -5"),
    ("--fault-seed", "x", "not an integer"),
    ("--drop-prob", "1", "--drop-prob"),
    ("--drop-prob", "nan", "--drop-prob"),
    ("--delay-rounds", "-1", "--delay-rounds -1"),
    ("--delay-rounds", "nan", "--delay-rounds 'nan'"),
    ("--delay-rounds", "1.5", "not a whole number"),
    ("--delay-rounds", "101", "from 0 to 100"),
    ("--delay-rounds", "99999999999999999999", "from 0 to 100"),
])
def test_bad_fault_values(fig1, tmp_path, capsys, flag, value, message):
    assert main(["resolve", "--links", str(fig1), "--out", str(tmp_path / "o.csv"),
                 flag, value]) == 2
    one_line_error(capsys, message)
    assert not (tmp_path / "o.csv").exists()


def test_delay_over_zenoh_is_refused(fig1, tmp_path, capsys):
    assert main(["resolve", "--links", str(fig1), "--out", str(tmp_path / "o.csv"),
                 "--transport", "zenoh", "--delay-rounds", "2"]) == 2
    one_line_error(capsys, "--delay-rounds")
    assert not (tmp_path / "o.csv").exists()


def test_crash_of_a_robot_that_does_not_exist(tmp_path, capsys):
    src = tmp_path / "in.csv"
    src.write_text("0,0,2147483646,0\n")  # compact ids: robots are cameras 0 and 2147483646
    assert main(["resolve", "--links", str(src), "--out", str(tmp_path / "o.csv"),
                 "--crash", "5@1"]) == 2
    one_line_error(capsys, "robot 5 does not exist")


def test_a_crash_of_a_robot_that_does_not_exist_is_refused_before_any_warning(tmp_path, capsys):
    """With the default rule (sync, not fault-tolerant) the warning that Alg. 1 runs instead
    came first, then the refusal: a refused command prints its error line only."""
    src = tmp_path / "in.csv"
    src.write_text("0,0,1,0\n1,0,2,0\n2,0,0,1\n")
    assert main(["resolve", "--links", str(src), "--out", str(tmp_path / "o.csv"),
                 "--crash", "9@1"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: --crash 9@1: robot 9 does not exist") and "warning" not in err
    assert not (tmp_path / "o.csv").exists()


@pytest.mark.parametrize("rule, flags, warned", [
    ("evidence", ["--crash", "1@999999"], "--resolution evidence is not fault-tolerant: with "
                                          "--crash the robots run the fault-tolerant Alg. 1"),
    ("sync", ["--switching-topology"], "--resolution sync is not fault-tolerant: with "
                                       "--switching-topology"),
    ("paper", ["--crash", "1@999999"], None),
    ("evidence", [], None),
])
def test_a_rule_that_gives_way_to_alg1_under_faults_is_warned(fig1, tmp_path, capsys, rule,
                                                               flags, warned):
    """A fault flag (even a crash that never fires) made the chosen rule run as Alg. 1
    without a word; the report said so only in resolution_method."""
    rep = tmp_path / "r.json"
    assert main(["resolve", "--links", str(fig1), "--out", str(tmp_path / "o.csv"),
                 "--resolution", rule, "--report", str(rep), *flags]) == 0
    err = capsys.readouterr().err
    assert (warned in err) if warned else ("not fault-tolerant" not in err), err
    method = json.loads(rep.read_text())["resolution_method"]
    assert method == ("paper" if warned else rule)


# ------------------------------------------------------------- wrong results as success

def _write_links(path, links):
    path.write_text("".join(f"{a},{b},{c},{d}\n" for a, b, c, d in zip(
        links.cam_i, links.feat_i, links.cam_j, links.feat_j, strict=True)))


def test_result_left_with_conflicts_exits_3_and_is_flagged(tmp_path, capsys):
    _, _, links = random_instance(np.random.default_rng(0), 6, 6, 1.0, 0.8)
    src, out, rep = tmp_path / "in.csv", tmp_path / "o.csv", tmp_path / "r.json"
    _write_links(src, links)
    crashes = [a for k in range(1, 6) for a in ("--crash", f"{k}@{k}")]
    code = main(["resolve", "--links", str(src), "--out", str(out), "--report", str(rep),
                 *crashes])
    report = json.loads(rep.read_text())
    assert report["after"]["conflictive_sets"] > 0  # the case this test is about
    assert code == 3
    assert report["conflict_free"] is False
    assert [w["code"] for w in report["warnings"]][0] == "not-conflict-free"
    err = capsys.readouterr().err
    assert "error: the result is not conflict-free" in err and "Traceback" not in err
    assert out.is_file()  # written, and flagged


@settings(max_examples=25, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(st.integers(0, 2**32 - 1), st.data())
def test_crashes_at_any_round_come_back_cut_with_a_reason_and_the_exit_status_says_so(
        tmp_path_factory, capsys, seed, data):
    """Crashes anywhere in the run (also after a robot's last detection): every input row is
    written back once; a crashed robot's links to the survivors are cut with a reason unless
    it confirmed the close (``crashed_after_close``); the exit status is 3 exactly when the
    written kept links hold a conflictive set (links left between crashed robots)."""
    from pipeline.association import AssociationGraph, count_conflicts
    from pipeline.consistency import resolve_conflicts
    from pipeline.consistency.protocols import ProtocolOptions
    from pipeline.types import Links

    fpc, _, links = random_instance(np.random.default_rng(seed), 6, 4, 0.7, 0.8)
    cams = sorted(set(links.cam_i.tolist()) | set(links.cam_j.tolist()))
    if not cams:
        return
    delay = data.draw(st.sampled_from([0, 0, 2]))
    total = resolve_conflicts(fpc, None, links, protocol=ProtocolOptions(reliable=True),
                              resolution="paper")
    total = (delay + 1) * total.stats["faults"]["rounds"]
    crashes = data.draw(st.dictionaries(st.sampled_from(cams), st.integers(0, total + 2),
                                        min_size=1, max_size=3))
    tmp = tmp_path_factory.mktemp("crash")
    src, out, rep = tmp / "in.csv", tmp / "o.csv", tmp / "r.json"
    _write_links(src, links)
    argv = ["resolve", "--links", str(src), "--out", str(out), "--report", str(rep),
            "--delay-rounds", str(delay)] + [f"--crash={k}@{r}" for k, r in crashes.items()]
    code = main(argv)
    assert "Traceback" not in capsys.readouterr().err
    report = json.loads(rep.read_text())
    rows = [r.split(",") for r in out.read_text().splitlines()[1:]]
    got = sorted(tuple(map(int, r[:4])) for r in rows)
    assert got == sorted(zip(links.cam_i.tolist(), links.feat_i.tolist(), links.cam_j.tolist(),
                             links.feat_j.tolist(), strict=True))  # every row once
    assert all((r[4] == "deleted") == (r[5] != "") for r in rows)  # cut <=> a reason
    f = report["faults"]
    dead = {int(k) for k in f["crashed"]}
    confirmed = {int(k) for k in f["crashed_after_close"]}
    for r in rows:
        a, b = int(r[0]), int(r[2])
        if (a in dead) != (b in dead) and not {a, b} & confirmed:
            assert r[4] == "deleted" and r[5] in ("robot-lost", "resolution"), (r, f)
    kept = [r for r in rows if r[4] == "kept"]
    kl = Links(*([int(r[c]) for r in kept] for c in range(4)))
    left = count_conflicts(AssociationGraph(fpc, kl)).conflictive_sets
    assert report["after"]["conflictive_sets"] == left
    assert code == (3 if left else 0)
    assert (report.get("conflict_free") is False) == bool(left)


def test_every_link_cut_as_robot_lost_is_said(tmp_path, capsys):
    _, _, links = random_instance(np.random.default_rng(0), 6, 6, 1.0, 0.8)
    src, rep = tmp_path / "in.csv", tmp_path / "r.json"
    _write_links(src, links)
    code = main(["resolve", "--links", str(src), "--out", str(tmp_path / "o.csv"),
                 "--report", str(rep), "--drop-prob", "0.99"])
    report = json.loads(rep.read_text())
    assert report["faults"]["links_cut_robot_lost"] == len(links)  # the case of this test
    assert code == 0  # conflict-free (nothing is left), but not silently
    codes = [w["code"] for w in report["warnings"]]
    assert "all-links-cut" in codes and "robots-lost-without-crash" in codes
    err = capsys.readouterr().err
    assert "warning: every one of the" in err and "never crashed" in err


def test_a_clean_run_has_no_flags(fig1, tmp_path):
    rep = tmp_path / "r.json"
    assert main(["resolve", "--links", str(fig1), "--out", str(tmp_path / "o.csv"),
                 "--report", str(rep)]) == 0
    report = json.loads(rep.read_text())
    assert "warnings" not in report and "conflict_free" not in report


# ----------------------------------------------------- memory follows the links, not the ids

@pytest.mark.parametrize("links,graph,first_row", [
    ("2147483646,0,0,0\n", None, "0,0,2147483646,0,kept"),
    ("0,100000000,1,0\n", None, "0,100000000,1,0,kept"),
    ("0,0,1,0\n1,1,2,1\n", "0,1\n1,2\n0,99999\n", "0,0,1,0,kept"),
])
def test_one_line_with_huge_ids_runs_in_small_memory(tmp_path, links, graph, first_row):
    src, out = tmp_path / "in.csv", tmp_path / "o.csv"
    src.write_text(links)
    args = ["resolve", "--links", src, "--out", out]
    if graph:
        (tmp_path / "g.csv").write_text(graph)
        args += ["--comm-graph", tmp_path / "g.csv"]
    proc = run_capped(args)  # under a 1.5 GB address-space cap
    assert proc.returncode == 0, proc.stderr
    rows = out.read_text().splitlines()
    assert len(rows) == 1 + links.count("\n")
    assert rows[1].startswith(first_row)  # ids written back as given


def test_noisy_links_chaining_one_giant_set_are_refused_before_allocating(tmp_path):
    """90,000 random links among 10 cameras: one association set of ~40,000 features, whose
    detection would need ~57 GB (the evidence rule's, ~2.5 GB); refused at once under a
    1.5 GB cap."""
    rng = np.random.default_rng(0)
    rows = []
    for i in range(10):
        for j in range(i + 1, 10):
            r, s = rng.permutation(4000)[:2000], rng.permutation(4000)[:2000]
            rows += [f"{i},{a},{j},{b}\n" for a, b in zip(r, s, strict=True)]
    src = tmp_path / "noisy.csv"
    src.write_text("".join(rows))
    for rule, part in (("paper", "distributed detection"),  # the rows of Sec. III
                       ("evidence", "evidence rule's detection")):  # up to B + 1 ids a feature
        proc = run_capped(["resolve", "--links", src, "--out", tmp_path / "o.csv",
                           "--resolution", rule])
        assert proc.returncode == 2 and "Traceback" not in proc.stderr
        assert part in proc.stderr and "into one association set" in proc.stderr
        assert "--max-memory-gb" in proc.stderr
        assert "--resolution sync" in proc.stderr  # the rule whose memory follows the links
        assert not (tmp_path / "o.csv").exists()


def test_the_sync_rule_counts_its_links_not_the_detections_sets(tmp_path):
    """300 cameras in a ring, 10 features each, every pair of neighbours swapping two matches:
    sets of up to 900 features, 2.5e6 detection entries (~90 MB): refused with the detection
    at 0.05 GB, counted per link by the sync rule (3,000 links: ~7 MB) and by the evidence
    rule (its lists: at most B + 1 = 54 ids a feature at 300 cameras, ~10 MB)."""
    rows = []
    for i in range(300):
        lo, hi = sorted((i, (i + 1) % 300))
        a = i % 9  # features a and 9 swapped on this pair
        rows += [f"{lo},{k},{hi},{ {a: 9, 9: a}.get(k, k)}\n" for k in range(10)]
    src = tmp_path / "ring.csv"
    src.write_text("".join(rows))
    refused = run_capped(["resolve", "--links", src, "--out", tmp_path / "o.csv",
                          "--resolution", "paper", "--max-memory-gb", "0.05"])
    assert refused.returncode == 2 and "into one association set" in refused.stderr
    for rule in ("sync", "evidence"):
        proc = run_capped(["resolve", "--links", src, "--out", tmp_path / "o.csv", "-q",
                           "--overwrite", "--resolution", rule, "--max-memory-gb", "0.05"])
        assert proc.returncode == 0, proc.stderr
    # with message loss the fault-tolerant Alg. 1 runs instead, and its detection is counted
    lossy = run_capped(["resolve", "--links", src, "--out", tmp_path / "o2.csv",
                        "--resolution", "sync", "--drop-prob", "0.1", "--max-memory-gb", "0.05"])
    assert lossy.returncode == 2 and "into one association set" in lossy.stderr


def test_memory_follows_the_links_not_the_cameras_squared(tmp_path):
    """12,000 cameras in 4,000 separate triangles: every robot held the offsets of all the
    cameras (1.3 GB); under the 1.5 GB cap it runs."""
    src = tmp_path / "triangles.csv"
    src.write_text("".join(f"{3 * k},0,{3 * k + 1},0\n{3 * k + 1},0,{3 * k + 2},0\n"
                           f"{3 * k},0,{3 * k + 2},0\n" for k in range(4000)))
    proc = run_capped(["resolve", "--links", src, "--out", tmp_path / "o.csv", "-q"])
    assert proc.returncode == 0, proc.stderr
    assert "12000 cameras" in proc.stdout


def test_the_memory_guard_counts_the_robots_of_every_camera(tmp_path, capsys):
    src = tmp_path / "pairs.csv"
    src.write_text("".join(f"{2 * k},0,{2 * k + 1},0\n" for k in range(1000)))
    refused(capsys, ["resolve", "--links", str(src), "--out", str(tmp_path / "o.csv"),
                     "--max-memory-gb", "0.01"], tmp_path, "robots of the 2000 cameras",
            "--max-memory-gb")


@pytest.mark.parametrize("value", ["nan", "0", "-1", "inf", "lots"])
def test_a_memory_limit_that_is_no_limit_is_refused(fig1, tmp_path, capsys, value):
    refused(capsys, ["resolve", "--links", str(fig1), "--out", str(tmp_path / "o.csv"),
                     "--max-memory-gb", value], tmp_path, f"--max-memory-gb {value!r}",
            "GB")


def test_a_faulty_run_that_would_take_minutes_is_refused_before_it_starts(tmp_path, capsys,
                                                                           monkeypatch):
    """--delay-rounds 100 (the stated maximum) on a 300-link path: (D + 1)(d + 3) = 30,603
    rounds of 301 robots ran past 120 s; refused at once, saying why."""
    import pipeline.consistency as consistency

    def never(*a, **k):
        raise AssertionError("the simulation started")

    src = tmp_path / "path.csv"
    src.write_text("".join(f"{i},0,{i + 1},0\n" for i in range(300)))
    monkeypatch.setattr(consistency, "resolve_conflicts", never)
    refused(capsys, ["resolve", "--links", str(src), "--out", str(tmp_path / "o.csv"),
                     "--delay-rounds", "100"], tmp_path, "30603 rounds", "--delay-rounds 100",
            "diameter 300")


# ------------------------------------------------------------------ rows of a text file

@pytest.mark.parametrize("which", ["--links", "--comm-graph"])
def test_a_field_longer_than_csv_reads_is_one_line(fig1, tmp_path, capsys, which):
    """CSV stops at fields of 131,072 characters (a _csv.Error traceback); such a line is
    refused, naming it, before CSV sees it."""
    graph = tmp_path / "g.csv"
    graph.write_text("0,1\n1,2\n2,3\n0,3\n")
    bad = tmp_path / "bad.csv"
    first = "0,0,1,0\n" if which == "--links" else "0,1\n"
    bad.write_text(first + '"' + "x" * 200_000 + '",2\n')
    argv = ["resolve", "--links", str(fig1), "--comm-graph", str(graph), "--out",
            str(tmp_path / "o.csv")]
    argv[argv.index(which) + 1] = str(bad)
    refused(capsys, argv, tmp_path, str(bad), "line 2", "longer than 65536 bytes")


def test_a_one_line_file_of_megabytes_is_refused_at_its_first_line(tmp_path, capsys):
    big = tmp_path / "big.csv"
    big.write_bytes(b"0," * 4_000_000)  # 8 MB, no line break
    refused(capsys, ["resolve", "--links", str(big), "--out", str(tmp_path / "o.csv")],
            tmp_path, "line 1", "longer than 65536 bytes")


@pytest.mark.parametrize("inside", ["\f", "\v", "\u2028", "\u2029", "\x85", "\x1c"])
def test_only_line_breaks_end_a_row(tmp_path, capsys, inside):
    """A form feed or U+2028 inside a row stays inside it: the row is wrong (named at its own
    line), never split into two rows."""
    src = tmp_path / "in.csv"
    src.write_text(f"0,0,1,0\n0,1,1,x{inside}\n", encoding="utf-8")
    refused(capsys, ["resolve", "--links", str(src), "--out", str(tmp_path / "o.csv")],
            tmp_path, f"{src}:2:")
    src.write_text(f"0,0,1,0{inside}1,0,2,0\n", encoding="utf-8")
    refused(capsys, ["resolve", "--links", str(src), "--out", str(tmp_path / "o.csv")],
            tmp_path, f"{src}:1:", "columns")


def test_a_carriage_return_inside_a_row_is_one_line(tmp_path, capsys):
    src = tmp_path / "in.csv"
    src.write_bytes(b"0,0,1,0\r\n1,0,\r2,0\n")
    refused(capsys, ["resolve", "--links", str(src), "--out", str(tmp_path / "o.csv")],
            tmp_path, f"{src}:2", "not a CSV row")


# ---------------------------------------------------------------------------- Ctrl-C

def test_ctrl_c_is_one_line_exit_130_and_nothing_written(fig1, tmp_path, capsys, monkeypatch):
    import pipeline.consistency as consistency

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(consistency, "resolve_conflicts", interrupted)
    out = tmp_path / "o.csv"
    assert main(["resolve", "--links", str(fig1), "--out", str(out)]) == 130
    err = capsys.readouterr().err
    assert err.strip().startswith("interrupted:") and "Traceback" not in err
    assert list(tmp_path.iterdir()) == [fig1]


def test_an_output_created_while_the_run_works_is_kept(fig1, tmp_path, capsys, monkeypatch):
    import pipeline.stages

    out, report = tmp_path / "o.csv", tmp_path / "r.json"
    stage = pipeline.stages.consistency_stage

    def someone_writes_out_meanwhile(*a, **k):
        out.write_text("made by another program")
        return stage(*a, **k)

    monkeypatch.setattr(pipeline.stages, "consistency_stage", someone_writes_out_meanwhile)
    assert main(["resolve", "--links", str(fig1), "--out", str(out), "--report",
                 str(report)]) == 2
    one_line_error(capsys, "--out", "created by someone else while this command worked")
    assert out.read_text() == "made by another program" and not report.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.csv", "o.csv"]


def test_a_report_that_cannot_be_written_names_it_and_leaves_no_output(fig1, tmp_path):
    import resource
    import subprocess

    def small_files():  # the links file fits, the report does not
        resource.setrlimit(resource.RLIMIT_FSIZE, (400, 400))

    out, report = tmp_path / "o.csv", tmp_path / "r.json"
    r = subprocess.run([sys.executable, "-m", "pipeline", "resolve", "--links", str(fig1),
                        "--out", str(out), "--report", str(report)], capture_output=True,
                       text=True, timeout=120, preexec_fn=small_files)
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr and f"error: {report}: File too large" in r.stderr
    assert "written" not in r.stdout
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.csv"]


def test_a_team_too_large_for_one_machine_is_refused_before_it_starts(tmp_path, capsys):
    """Over zenoh each camera is a process: a links file naming 301 cameras is refused at
    once (it would fork 301 processes), and a camera id with no link starts none (ids made
    compact): the same cameras counted and the same links.csv as the simulator's."""
    from pipeline.runs.transports.zenoh import MAX_ROBOT_PROCESSES

    chain = tmp_path / "chain.csv"
    n = MAX_ROBOT_PROCESSES + 45
    chain.write_text("".join(f"{i},0,{i + 1},0\n" for i in range(n - 1)))
    assert main(["resolve", "--links", str(chain), "--out", str(tmp_path / "o.csv"),
                 "--transport", "zenoh"]) == 2
    one_line_error(capsys, f"{n} cameras in the links file would be {n} processes")
    assert not (tmp_path / "o.csv").exists()
    gap = tmp_path / "gap.csv"
    gap.write_text("0,0,100,0\n")
    outs = []
    for transport in ("sim", "zenoh"):
        out = tmp_path / f"{transport}.csv"
        assert main(["resolve", "--links", str(gap), "--out", str(out), "--transport",
                     transport]) == 0
        assert "2 cameras, 1 comm edges, 1 links" in capsys.readouterr().out
        outs.append(out.read_bytes())
    assert outs[0] == outs[1]
