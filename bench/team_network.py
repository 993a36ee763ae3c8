"""Benchmark: a team on real links — every robot on its own host, faults made by the network.

Each robot runs as ``python -m pipeline robot`` in its own Linux network namespace, one cable
(veth pair) per comm edge (:mod:`pipeline.team.netns`); needs root. Teams: formation d (6
robots) and a 20-robot ring2 formation (``--robots``), both at ``--size`` with fusion on (the
default ``run-formation``). Cases, side by side in one run:

* ``unlimited``, ``10mbit``, ``1mbit``: a ``tbf`` cap on both ends of every cable
  (``256kbit`` too when named in ``--cases``);
* ``partition``: cable ``(1, 2)`` down for ``--fault-s`` seconds, then up again;
* ``freeze``: robot 2's program stopped (SIGSTOP) for ``--fault-s`` seconds, then resumed;
* ``kill``: robot 2's program killed (SIGKILL).

Faults start ``--fault-after`` seconds after robot 2's start handshake. (Loss, delay and
reordering on the wire need ``netem``, absent from this kernel: not measured.)

Columns per case: wall time (first robot started to last robot ended, process start
included), rounds (most of any robot), each robot's outcome, conflictive sets of the links
kept, links lost (links of the unlimited run that are missing or cut ``robot-lost``), links
decided differently from the unlimited run, and per cable: bytes counted by the protocol
(messages, as the simulator counts), bytes of the packets handed to Zenoh, and bytes that
crossed the cable (kernel interface counters, both directions, headers included), with the
time the busiest direction's bytes alone need at the cap (the physical limit); and the TCP
segments the hosts sent and retransmitted (``nstat``). Saves
``runs/bench-team-network/results.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.errors import one_line_interrupts  # noqa: E402

one_line_interrupts(__name__, __file__)  # a Ctrl-C while the libraries below load

from pipeline.commands.options import size_argument  # noqa: E402
from pipeline.consistency.robot import ROBOT_LOST  # noqa: E402
from pipeline.errors import one_line_errors  # noqa: E402
from pipeline.outputs import results_folder_problem  # noqa: E402
from pipeline.runfolder import write_json_atomic  # noqa: E402
from pipeline.team.netns import (  # noqa: E402
    NETEM_MISSING,
    NetnsRig,
    conflictive_sets_after,
    read_results,
    team_links,
    unavailable,
    wait_for_line,
)

RATES = {"unlimited": None, "10mbit": 10e6, "1mbit": 1e6, "256kbit": 256e3}
CASES = ("unlimited", "10mbit", "1mbit", "partition", "freeze", "kill")  # and 256kbit


def _rate_bits(name: str) -> float | None:
    return RATES.get(name)


def run_case(team_name: str, data: dict, edges, case: str, args, workdir: Path) -> dict:
    """One team run of ``case`` on a fresh rig; the raw figures."""
    n = int(data["robots"] or 6)
    with NetnsRig(n, edges) as rig:
        if RATES.get(case):
            rig.cap(case)
        team = rig.team(team_name, data, {"fusion": True, "start_timeout_s": 120.0})
        t0 = time.monotonic()
        paths = rig.start_robots(team, workdir)
        fault = None
        if case in ("partition", "freeze", "kill"):
            if not wait_for_line(workdir / "robot2.log", "neighbours heard", 120):
                raise RuntimeError(f"{case}: robot 2 did not finish its start handshake")
            time.sleep(args.fault_after)
            fault = {"at_s": round(time.monotonic() - t0, 2)}
            if case == "partition":
                rig.link(1, 2, up=False)
                time.sleep(args.fault_s)
                rig.link(1, 2, up=True)
            elif case == "freeze":
                rig.signal(2, signal.SIGSTOP)
                time.sleep(args.fault_s)
                rig.signal(2, signal.SIGCONT)
            else:
                rig.signal(2, signal.SIGKILL)
            fault["end_s"] = round(time.monotonic() - t0, 2)
        ends = {}
        while len(ends) < n and time.monotonic() - t0 < args.limit_s:
            for i, p in rig.procs.items():
                if i not in ends and p.poll() is not None:
                    ends[i] = time.monotonic() - t0
            time.sleep(0.05)
        wall = max(ends.values()) if len(ends) == n else None
        codes = {i: p.poll() for i, p in rig.procs.items()}
        ifaces = {f"{a}-{b}": {"tx_a": rig.interface_bytes(a, b)[0],
                               "tx_b": rig.interface_bytes(b, a)[0]} for a, b in rig.edges}
        tcp = [rig.tcp_counters(i) for i in range(n)]
    res = read_results(paths)
    return {"case": case, "wall_s": None if wall is None else round(wall, 2),
            "hung": wall is None, "exit_codes": codes, "fault": fault, "results": res,
            "interfaces": ifaces,
            "tcp_segments": sum(c.get("TcpOutSegs", 0) for c in tcp),
            "tcp_retransmitted": sum(c.get("TcpRetransSegs", 0) for c in tcp)}


def summarize(raw: dict, edges, reference: dict | None) -> dict:
    """The bench's row for one case (module docstring)."""
    res = raw["results"]
    rate = _rate_bits(raw["case"])
    links = {}
    need = 0.0
    for a, b in edges:
        key = f"{a}-{b}"
        ca, cb = res.get(a, {}).get("counters", {}), res.get(b, {}).get("counters", {})
        counted = int(ca.get("bytes_to", {}).get(str(b), 0) + cb.get("bytes_to", {}).get(str(a), 0))
        packets = int(ca.get("wire_bytes_to", {}).get(str(b), 0)
                      + cb.get("wire_bytes_to", {}).get(str(a), 0))
        tx = raw["interfaces"][key]
        socket = tx["tx_a"] + tx["tx_b"]
        links[key] = {"counted": counted, "packets": packets, "socket": socket}
        if rate:
            need = max(need, 8.0 * max(tx["tx_a"], tx["tx_b"]) / rate)
    decisions = team_links(res) if res else {}
    lost = differ = None
    if reference is not None:
        ref = reference
        lost = differ = 0
        for k, ends in ref.items():
            now = decisions.get(k)
            ref_alive = all(a for a, _, _ in ends.values())
            if now is None or any(c == ROBOT_LOST for _, c, _ in now.values()):
                lost += 1
                continue
            if all(a for a, _, _ in now.values()) != ref_alive:
                differ += 1
    timings = [doc["timings_s"].get("total", 0.0) for doc in res.values()]
    return {
        "case": raw["case"], "wall_s": raw["wall_s"], "hung": raw["hung"],
        "fault": raw["fault"],
        "exit_codes": {str(k): v for k, v in sorted(raw["exit_codes"].items())},
        "rounds": max((doc["counters"]["round"] for doc in res.values()), default=None),
        "outcomes": {str(i): doc["counters"]["outcome"] for i, doc in sorted(res.items())},
        "written_off": {str(i): doc["counters"]["written_off"] for i, doc in sorted(res.items())
                        if doc["counters"]["written_off"]},
        "conflictive_sets_after": conflictive_sets_after(res) if res else None,
        "links": len(decisions), "links_lost": lost, "links_decided_differently": differ,
        "bytes_counted": sum(v["counted"] for v in links.values()),
        "bytes_packets": sum(v["packets"] for v in links.values()),
        "bytes_socket": sum(v["socket"] for v in links.values()),
        "bytes_alone_need_s": round(need, 2) if rate else None,
        "robot_total_s_max": round(max(timings), 2) if timings else None,  # waits included
        # seconds the robot's round packets waited to be handed to Zenoh (a full queue)
        "robot_send_s_max": max((doc["counters"].get("send_s", 0.0) for doc in res.values()),
                                default=None),
        # TCP segments all hosts sent, and retransmitted (a capped cable's bucket drops)
        "tcp_segments": raw["tcp_segments"], "tcp_retransmitted": raw["tcp_retransmitted"],
        "per_link": links,
    }


def table(out: dict) -> list[str]:
    """The saved results as the README's markdown table, one row per team and case: wall,
    rounds, outcomes, conflictive sets after, links lost (of the unlimited run's), links
    decided otherwise, MB counted / packets / on the cables, the busiest cable's MB (both
    directions) and the seconds its busiest direction alone needs at the cap."""
    lines = ["| team | case | wall | rounds | outcomes | conflictive sets after | links lost | "
             "decided otherwise | MB counted / packets / on the cables | busiest cable | "
             "bytes alone need |",
             "|---|---|---:|---:|---|---:|---:|---:|---:|---:|---:|"]
    for name, team in out["teams"].items():
        label = "d" if name == "d" else f"{name}, {team['robots']}"
        links = next((r["links"] for r in team["rows"] if r["case"] == "unlimited"), None)
        for r in team["rows"]:
            counts = {}
            for o in r["outcomes"].values():
                counts[o] = counts.get(o, 0) + 1
            outcomes = ", ".join(f"{o} {k}" for o, k in sorted(counts.items())) or "none"
            busiest = max((v["socket"] for v in r["per_link"].values()), default=0)
            lost = "–" if r["links_lost"] is None else f"{r['links_lost']} of {links}"
            need = "–" if r["bytes_alone_need_s"] is None else f"{r['bytes_alone_need_s']:.2f} s"
            lines.append(
                f"| {label} | {r['case']} | {r['wall_s']:.2f} s | {r['rounds']} | {outcomes} | "
                f"{r['conflictive_sets_after']} | {lost} | "
                f"{'–' if r['links_decided_differently'] is None else r['links_decided_differently']}"
                f" | {r['bytes_counted'] / 1e6:.2f} / {r['bytes_packets'] / 1e6:.2f} / "
                f"{r['bytes_socket'] / 1e6:.2f} | {busiest / 1e6:.2f} MB | {need} |")
    return lines


@one_line_errors
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--teams", default="d,ring2", help="comma list of d, ring2")
    ap.add_argument("--cases", default=",".join(CASES),
                    help=f"comma list of {', '.join(CASES)}, 256kbit (the first is the "
                         "reference of links lost: name unlimited first)")
    ap.add_argument("--robots", type=int, default=20, help="robots of the ring2 team")
    ap.add_argument("--size", default="640x480", type=size_argument,
                    help="image size WxH of every robot")
    ap.add_argument("--fault-s", type=float, default=10.0, help="partition / freeze length")
    ap.add_argument("--fault-after", type=float, default=1.0,
                    help="seconds after robot 2's start handshake at which the fault starts")
    ap.add_argument("--limit-s", type=float, default=900.0,
                    help="a robot still running this long after the start counts as hung")
    ap.add_argument("--out", default=str(ROOT / "runs" / "bench-team-network"))
    ap.add_argument("--reprint", metavar="RESULTS_JSON",
                    help="print the table of a saved results.json and stop (runs nothing)")
    args = ap.parse_args(argv)
    if args.reprint:
        try:
            saved = json.loads(Path(args.reprint).read_text())
            print("\n".join(table(saved)))
        except (OSError, ValueError, KeyError, TypeError) as exc:
            ap.error(f"--reprint {args.reprint}: not this bench's results.json ({exc})")
        return 0
    if problem := results_folder_problem(args.out):
        ap.error(problem)
    for flag, given, known in (("--teams", args.teams, ("d", "ring2")),
                               ("--cases", args.cases, (*CASES, *RATES))):
        names = [t for t in given.split(",") if t]
        if not names or set(names) - set(known):
            bad = sorted(set(names) - set(known)) or [repr(given)]
            ap.error(f"{flag} {','.join(bad)}: expected a comma list of "
                     f"{', '.join(dict.fromkeys(known))}")
    if args.robots < 2:
        ap.error(f"--robots {args.robots}: a team has at least 2 robots")
    why = unavailable()
    if why:
        print(f"cannot run: {why}", file=sys.stderr)
        return 2
    # a SIGTERM (timeout, kill) unwinds as Ctrl-C does: each rig removes its namespaces
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(128 + signal.SIGTERM))
    import data_synth

    w, h = (int(v) for v in args.size.lower().split("x"))
    teams = {"d": {"kind": "formation", "formation": "d", "seed": 0, "size": [w, h],
                   "robots": None, "graph": None},
             "ring2": {"kind": "formation", "formation": "d", "seed": 0, "size": [w, h],
                       "robots": int(args.robots), "graph": "ring2"}}
    out = {"netem": NETEM_MISSING, "size": [w, h], "fault_s": args.fault_s,
           "fault_after_s": args.fault_after, "load_average_start": os.getloadavg()[0],
           "teams": {}}
    print(f"load average at the start: {out['load_average_start']:.1f}", flush=True)
    t_all = time.monotonic()
    for name in [t for t in args.teams.split(",") if t]:
        data = teams[name]
        edges = data_synth.formation_edges(data["formation"], 0, data["robots"], data["graph"])
        n = int(data["robots"] or 6)
        rows, reference = [], None
        for case in [c for c in args.cases.split(",") if c]:
            with tempfile.TemporaryDirectory(prefix="fm-net-") as tmp:
                raw = run_case(f"net-{name}", data, edges, case, args, Path(tmp))
            if case == "unlimited":
                reference = team_links(raw["results"])
            row = summarize(raw, [tuple(e) for e in edges.tolist()], reference)
            rows.append(row)
            print(f"{name} ({n} robots) {case:>9}: wall {row['wall_s']} s, rounds "
                  f"{row['rounds']}, outcomes {sorted(set(row['outcomes'].values()))}, "
                  f"conflictive sets {row['conflictive_sets_after']}, links lost "
                  f"{row['links_lost']}, differ {row['links_decided_differently']}, bytes "
                  f"counted {row['bytes_counted']:,} / packets {row['bytes_packets']:,} / "
                  f"socket {row['bytes_socket']:,}, bytes alone need "
                  f"{row['bytes_alone_need_s']} s, TCP segments retransmitted "
                  f"{row['tcp_retransmitted']:,} of {row['tcp_segments']:,}", flush=True)
        out["teams"][name] = {"robots": n, "edges": len(edges), "rows": rows}
    out["bench_s"] = round(time.monotonic() - t_all, 1)
    out["load_average_end"] = os.getloadavg()[0]
    print(f"load average at the end: {out['load_average_end']:.1f}")
    Path(args.out).mkdir(parents=True, exist_ok=True)
    write_json_atomic(Path(args.out) / "results.json", json.loads(json.dumps(out)))
    print(f"saved {args.out}/results.json ({out['bench_s']} s)")
    print("\n".join(table(out)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
