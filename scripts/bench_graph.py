#!/usr/bin/env python3
"""Benchmarks S4 and S5 of the node graph (docs/benchmarks.md, quality.md "Speed").

S4: lockstep mode, recording on (all five nodes), at each control rate of --rates (default
    1, 2, 5 and 10 kHz; the params file's physics step): real-time factor = simulated
    seconds / wall seconds of a --duration run (default 10 s), median of --runs (default
    3). The wall time runs from tick 0 to the last tick, as the sim reports it.
S5: realtime mode, 1 kHz, all five nodes: percentage of ticks whose command arrived
    within its period, over --duration seconds (median of --runs).

Each run starts a fresh graph on its own ROS_DOMAIN_ID and prints the CPU seconds every
node used, so a slow figure says where the time went.

S5 runs the control path (the sim's and the controllers' main and Fast DDS receive threads)
under SCHED_FIFO at --rt-priority (default 20, what ``run_graph.sh --mode realtime`` uses;
0 = normal scheduling, to measure without it); S4 (lockstep) runs with normal scheduling
unless --s4-rt-priority says otherwise. Without the privilege the nodes say so and run
normally, and this script prints it.

Each run first measures how much of a core a busy loop gets for 1 s: the machine is
shared with load that ps does not show, and the figures move with it.

With --breakdown every node records timestamps of its per-tick work
(``hexapod_common.core.trace``, HEXAPOD_TRACE_DIR) and each S4 run prints where a tick's wall
time goes (``hexapod_common.core.trace_breakdown``): DDS delivery (the samples' source and
reception timestamps), wake-ups, takes, verification, decoding, checks, the control law,
encoding, signing, publishing, the physics step; the segments add up to the tick period.
Tracing costs a few microseconds per event, so the breakdown runs are a little slower than
untraced ones: take S4's figure from a run without it. --auth off runs the graph without
message authentication (to measure what it costs).

S4 as a user sees it (--only s4user): the whole command ``scripts/run_graph.sh --mode lockstep
    --controller pd_pf --control-rate 1000`` (its default switch included) timed by the wall
    clock for 20 s and for 5 s of simulated time, alternating, --runs pairs; start-up and
    end-of-run work that does not grow with the run cancel in the difference: real-time
    factor = 15 s / (wall(20 s) - wall(5 s)), and the same for each pair.

Usage: scripts/bench_graph.py [--runs 3] [--duration 10] [--only s4|s5|s4user] [--rates 1000,2000]
       [--rt-priority 20] [--s4-rt-priority 0] [--breakdown] [--auth on|off]
(run through `scripts/env.sh`, or it re-executes itself inside it).
"""
from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
import host_speed
from project_env import reexec_in_env

ROOT = Path(__file__).resolve().parent.parent


SUMMARY = re.compile(r"stopped at tick (\d+) .*?: (\d+) missed, (\d+) late, (\d+) on time"
                     r".*wall ([\d.]+) s, real-time factor ([\d.]+)")
NODES = ("metrics", "trajectory_generator", "pd_p_controller", "pd_pf_controller")
CPU_COLUMNS = ("hexapod_sim",) + NODES


def run_graph(mode: str, duration: float, domain: int, log_dir: Path, rt_priority: int = 0,
              rate: float = 1000.0, trace_dir: Path | None = None, auth: str = "on"
              ) -> dict[str, float]:
    """One graph run at control rate ``rate`` (Hz), the control path under SCHED_FIFO at
    ``rt_priority`` (0: normal scheduling); the sim's summary figures, each node's CPU
    seconds and whether every control-path node got SCHED_FIFO; with ``trace_dir`` every
    node writes its trace there."""
    from hexapod_bringup.cmd_graph import RT_PRIORITY_NODES, GraphProcesses
    from hexapod_common.core.msg_auth import AUTH_ENV
    from hexapod_common.core.trace import TRACE_ENV

    env = {"ROS_DOMAIN_ID": str(domain), AUTH_ENV: auth}
    if trace_dir is not None:
        trace_dir.mkdir(parents=True, exist_ok=True)
        env[TRACE_ENV] = str(trace_dir)
    g = GraphProcesses(log_dir, env=env, overrides=(f"sim.control_period:={1.0 / rate!r}",),
                       rt_priority=rt_priority)
    try:
        g.start("metrics", f"bag_path:={log_dir / 'bag'}")
        for name in NODES[1:]:
            g.start(name)
        g.start("hexapod_sim", "stop_at_end:=true", f"run.duration:={duration}",
                f"sim.mode:={mode}")
        g.wait_log("hexapod_sim", "real-time factor", timeout=duration * 20 + 120)
        cpu = {n: g.cpu_seconds(n) for n in NODES}
        try:
            cpu["hexapod_sim"] = g.cpu_seconds("hexapod_sim")
        except (OSError, IndexError):  # already gone
            cpu["hexapod_sim"] = float("nan")
        g.wait_exit("hexapod_sim", 30)
    finally:
        g.stop_all(order=("trajectory_generator", "pd_p_controller", "pd_pf_controller",
                          "metrics"))
    m = SUMMARY.search(g.log("hexapod_sim"))
    if m is None:
        raise RuntimeError(f"no summary in {log_dir / 'hexapod_sim.log'}")
    ticks, missed, late, on_time = (int(x) for x in m.groups()[:4])
    rt = re.search(r"round trip median ([\d.na]+) ms, p99 ([\d.na]+) ms", g.log("hexapod_sim"))
    granted = all(f"rt_priority {rt_priority}: SCHED_FIFO" in g.log(n)
                  for n in RT_PRIORITY_NODES if n in g.procs)
    return {"rt": rt_priority if granted else 0,
            "ticks": ticks, "missed": missed, "late": late, "on_time": on_time,
            "rt_median": float(rt.group(1)) if rt else float("nan"),
            "rt_p99": float(rt.group(2)) if rt else float("nan"),
            "wall": float(m.group(5)), "rtf": float(m.group(6)), **{f"cpu_{n}": c for n, c
                                                                  in cpu.items()}}


def print_breakdown(trace_dir: Path, rate: float) -> None:
    """Print the traced run's tick breakdown (hexapod_common.core.trace_breakdown)."""
    from hexapod_common.core.params import load_params
    from hexapod_common.core.trace_breakdown import breakdown, format_breakdown, load

    b = breakdown(load(trace_dir), load_params().run.controller)
    print(f"breakdown of a lockstep tick at {rate / 1000:g} kHz over {b.ticks} ticks (ms; "
          f"load average {os.getloadavg()[0]:.2f}):")
    print("\n".join(format_breakdown(b)), flush=True)


def cpu_available(seconds: float = 1.0) -> float:
    """Share of wall time a busy loop actually runs (gaps > 1 ms count as lost): the
    machine is shared, and other tenants' load (invisible to ps) shows up here."""
    start = last = time.perf_counter()
    lost = 0.0
    while last - start < seconds:
        now = time.perf_counter()
        if now - last > 1e-3:
            lost += now - last
        last = now
    return 1.0 - lost / (last - start)


HOLDS = re.compile(r"(\d+) holds for the recorder \(([\d.]+) s\)")


def s4_as_a_user_sees_it(pairs: int, base: int) -> int:
    """S4 as a user sees it: ``run_graph.sh`` timed whole for 20 s and 5 s of simulated time,
    alternating; the real-time factor of the difference, per pair and the median. Where the
    user's figure parts from the tick loop's: each run's wall time split into the sim's tick
    loop (its summary: tick 0 to the last tick, the default switch and recorder holds
    included) and the rest (start-up, then the end: bag closing, indices, the table)."""
    script = Path(__file__).resolve().parent / "run_graph.sh"
    walls: dict[float, list[float]] = {5.0: [], 20.0: []}
    loops: dict[float, list[float]] = {5.0: [], 20.0: []}
    held: dict[float, list[float]] = {5.0: [], 20.0: []}
    with tempfile.TemporaryDirectory(prefix="bench_graph_user_") as tmp:
        for i in range(pairs):
            for duration in (20.0, 5.0) if i % 2 else (5.0, 20.0):
                env = {**os.environ, "ROS_DOMAIN_ID": str((base + 3 * i) % 101 + 1)}
                bag = Path(tmp) / f"bag_{i}_{duration:g}"
                t0 = time.monotonic()
                r = subprocess.run([str(script), "--mode", "lockstep", "--controller", "pd_pf",
                                    "--control-rate", "1000", "--duration", f"{duration:g}",
                                    "--bag", str(bag)],
                                   env=env, capture_output=True, text=True)
                wall = time.monotonic() - t0
                if r.returncode != 0:
                    print(f"run_graph.sh --duration {duration:g} exited {r.returncode}: "
                          f"{r.stderr.strip().splitlines()[-1:]}", file=sys.stderr)
                    return 1
                log = (Path(f"{bag}_logs") / "hexapod_sim.log").read_text(errors="replace")
                m, h = SUMMARY.search(log), HOLDS.search(log)
                if m is None or h is None:
                    print(f"no summary in the sim's log of --duration {duration:g}",
                          file=sys.stderr)
                    return 1
                loop, hold_s = float(m.group(5)), float(h.group(2))
                walls[duration].append(wall)
                loops[duration].append(loop)
                held[duration].append(hold_s)
                print(f"pair {i + 1}: --duration {duration:g}: wall {wall:.2f} s, of which the "
                      f"tick loop {loop:.2f} s (recorder holds {h.group(1)}, {hold_s:.2f} s), "
                      f"the rest {wall - loop:.2f} s", flush=True)
    rtfs = [15.0 / (b - a) for a, b in zip(walls[5.0], walls[20.0])]
    loop_rtfs = [15.0 / (b - a) for a, b in zip(loops[5.0], loops[20.0])]
    rest = {d: statistics.median(w - lp for w, lp in zip(walls[d], loops[d])) for d in walls}
    print("S4 as a user sees it (run_graph.sh, lockstep, pd_pf, 1 kHz, 20 s - 5 s): "
          + ", ".join(f"{x:.2f}" for x in rtfs)
          + f"; median {statistics.median(rtfs):.2f}  (>= 2.5); start-up and end (wall(5 s) "
          f"- 5 s / factor): {statistics.median(walls[5.0]) - 5.0 / statistics.median(rtfs):.2f} s")
    print("  the sim's tick loop alone (20 s - 5 s): "
          + ", ".join(f"{x:.2f}" for x in loop_rtfs)
          + f"; median {statistics.median(loop_rtfs):.2f}; recorder holds (median) "
          f"{statistics.median(held[5.0]):.2f} s at 5 s, {statistics.median(held[20.0]):.2f} s "
          f"at 20 s; outside the tick loop (start-up and end, median) {rest[5.0]:.2f} s at 5 s, "
          f"{rest[20.0]:.2f} s at 20 s")
    return 0


def main() -> int:
    reexec_in_env(__file__)
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--only", choices=("s4", "s5", "s4user"))
    ap.add_argument("--rates", default="1000,2000,5000,10000",
                    help="S4: control rates in Hz, comma-separated (S5 runs at 1 kHz)")
    ap.add_argument("--rt-priority", type=int, default=20, dest="rt_priority",
                    help="S5: SCHED_FIFO priority of the control path (0 = normal scheduling)")
    ap.add_argument("--s4-rt-priority", type=int, default=0, dest="s4_rt_priority",
                    help="S4: the same for the lockstep runs (default 0)")
    ap.add_argument("--breakdown", action="store_true",
                    help="S4: trace every node and print where each tick's time goes")
    ap.add_argument("--auth", choices=("on", "off"), default="on",
                    help="message authentication of the graph (default on)")
    args = ap.parse_args()
    print(f"machine: {os.cpu_count()} cores, {host_speed.describe()}, "
          f"load average {os.getloadavg()[0]:.2f}, "
          f"authentication {args.auth}, recorder at nice 10; control path under SCHED_FIFO "
          f"{args.s4_rt_priority} in S4, {args.rt_priority} in S5 (0 = normal scheduling)")
    base = 150 + os.getpid() % 80
    if args.only == "s4user":
        return s4_as_a_user_sees_it(args.runs, base)
    with tempfile.TemporaryDirectory(prefix="bench_graph_") as tmp:
        rates = [float(x) for x in args.rates.split(",")]
        plan = [("s4", "lockstep", r) for r in rates] + [("s5", "realtime", 1000.0)]
        for j, (key, mode, rate) in enumerate(plan):
            if args.only and args.only != key:
                continue
            rows = []
            for i in range(args.runs):
                avail = cpu_available()
                run_dir = Path(tmp) / f"{key}_{j}_{i}"
                traced = args.breakdown and key == "s4"
                prio = args.rt_priority if key == "s5" else args.s4_rt_priority
                r = run_graph(mode, args.duration, (base + 7 * j + i) % 101 + 1, run_dir,
                              prio, rate, run_dir / "trace" if traced else None, args.auth)
                rows.append(r)
                cpu = ", ".join(f"{n} {r['cpu_' + n]:.1f}" for n in CPU_COLUMNS)
                print(f"{key} {rate / 1000:g} kHz run {i + 1} (a busy loop got "
                      f"{100 * avail:.0f} % of a core just "
                      f"before; SCHED_FIFO {r['rt'] or 'no'}): {r['ticks']} ticks, "
                      f"wall {r['wall']:.2f} s, "
                      f"real-time factor {r['rtf']:.3f}, missed {r['missed']}, late "
                      f"{r['late']}, on time {r['on_time']}, round trip median "
                      f"{r['rt_median']:.2f} ms p99 {r['rt_p99']:.2f} ms; CPU s: {cpu}",
                      flush=True)
                if traced:
                    print_breakdown(run_dir / "trace", rate)
            if key == "s4":
                med = statistics.median(r["rtf"] for r in rows)
                target = {1000.0: ">= 2.5", 2000.0: ">= 1.2"}.get(rate, "no target")
                print(f"S4 lockstep real-time factor ({rate / 1000:g} kHz, recording on), "
                      f"median of {len(rows)}: {med:.3f}  ({target})", flush=True)
            else:
                pct = [100.0 * r["on_time"] / max(r["ticks"], 1) for r in rows]
                print(f"S5 realtime ticks on time (1 kHz), median of {len(rows)}: "
                      f"{statistics.median(pct):.2f} %  (target >= 99 %); missed "
                      f"{[r['missed'] for r in rows]}, late {[r['late'] for r in rows]}")
    print(f"load average after: {os.getloadavg()[0]:.2f}; {host_speed.describe()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
