#!/usr/bin/env python3
"""Realtime switching (S5, docs/benchmarks.md): lost switch ticks and on-time ticks.

Each run starts a fresh graph in realtime mode (1 kHz by default) on its own
ROS_DOMAIN_ID, and, with --switches N, hands control back and forth N times, one switch
every --every simulated seconds, through the sim's standard ``set_parameters`` service from
one client node that joined before tick 0 (what `hexapod switch` does, without a new
process per switch), or with --via tool by running scripts/switch_controller.sh (a new
process per switch, through the sim's local switch channel: what a user does), or
with --via channel through that channel from this process (no process per switch). For each
switch the sim logged, it counts from the bag the ticks from the one before the switch to 3
after it that no command of the controller named in the state answered (late or not): a
switch with any such tick *lost a tick* (a state missing from the bag counts as lost; each
line gives the bag's count of states against the sim's). It also prints the share of ticks
whose command arrived within its period, with and without switching.

--hog adds one CPU hog (a busy loop in its own process) beside the graph. The control path
runs under SCHED_FIFO at --rt-priority (default 20, as ``run_graph.sh --mode realtime``
sets it; 0 = normal scheduling).

--kill-idle S runs two graphs without switches side by side in time (one after the other)
and kills the idle controller (SIGKILL) S wall seconds into the second one; from the sim's
status messages in each bag it prints the share of on-time ticks before and after that
moment, so a dead idle controller's cost shows against the same run without a kill.

Usage: scripts/bench_switch.py [--switches 50] [--every 0.2] [--period 0.001] [--hog]
       [--rt-priority 20] [--via service|tool|channel]
       [--no-baseline] [--kill-idle S] [--keep DIR] [--set NAME=VALUE ...]
(run through `scripts/env.sh`, or it re-executes itself inside it).
"""
from __future__ import annotations

import argparse
import contextlib
import multiprocessing
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Iterator
from project_env import reexec_in_env

ROOT = Path(__file__).resolve().parent.parent
ALL = "trajectory_generator,pd_p_controller,pd_pf_controller,metrics,bench_switch"
#: What each --via switches through (the benchmark's first line).
VIA = {"service": "set_parameters", "tool": "switch_controller.sh",
       "channel": "the sim's local switch channel"}
SUMMARY = re.compile(r"stopped at tick (\d+) .*?: (\d+) missed, (\d+) late, (\d+) on time")


@contextlib.contextmanager
def _work_dir(keep: Path | None) -> Iterator[str]:
    """Where the runs write their logs and bags: ``keep`` (created, kept) or a temporary
    directory (removed at the end)."""
    if keep is not None:
        if keep.exists() and any(keep.iterdir()):
            raise SystemExit(f"bench_switch.py: error: --keep {keep}: not an empty directory")
        keep.mkdir(parents=True, exist_ok=True)
        yield str(keep)
        return
    with tempfile.TemporaryDirectory(prefix="bench_switch_") as tmp:
        yield tmp


def _hog() -> None:
    while True:
        pass


#: The sim's log line of each switch (sim_node.py): the tick the new controller took over.
SWITCHED = re.compile(r"switched \w+ -> \w+ at tick (\d+)")


def lost_ticks(bag: Path, period_ns: int, at: list[int]) -> tuple[list[int], int, int]:
    """(lost ticks per switch, states in the bag, states expected) around the switch ticks
    ``at`` (the sim's, or the same schedule in a run without switches): the ticks from the
    one before to 3 after that no command of the controller named in the state answered.
    A tick whose state is not in the bag counts as lost (the states' count says why)."""
    from hexapod_metrics.bag import open_bag
    from hexapod_common.runtime import conversions as C
    from hexapod_common.core import topics as T
    from hexapod_common.core.labels import in_charge

    frames: dict[str, dict[int, str]] = {T.JOINT_STATES: {}, T.JOINT_COMMANDS: {}}
    with open_bag(bag) as b:
        for topic, out in frames.items():
            codec = C.CODECS[topic]
            for _, _, data in b.messages([topic]):
                msg = codec.decode(bytes(data))
                # the states' frame_id also says whether the torque was held (core/labels.py)
                out[C.tick_of(msg.stamp_ns, period_ns)] = in_charge(msg.frame_id)
    states, commands = frames[T.JOINT_STATES], frames[T.JOINT_COMMANDS]
    n = max(states)
    lost = [sum(1 for j in range(s - 1, min(n, s + 4))
                if j not in states or commands.get(j) != states[j]) for s in at]
    return lost, len(states), n + 1


def on_time_split(bag: Path, at_tick: int
                  ) -> tuple[float, float, float, float, list[float]]:
    """(% on time before, after ``at_tick``, median real-time factor before, after, % on
    time in each of the sim's status intervals (0.5 wall s) after ``at_tick``) from the sim's
    status messages in ``bag``."""
    import numpy as np

    from hexapod_common.core import cdr
    from hexapod_metrics.bag import open_bag
    from hexapod_common.core import topics as T

    rows = []
    with open_bag(bag) as b:
        for _, _, data in b.messages([T.STATUS]):
            for st in cdr.decode_diagnostic_array(bytes(data))[1]:
                if st.name == "hexapod_sim":
                    v = dict(st.values)
                    rows.append((int(v["tick"]), int(v["on_time_ticks"]),
                                 float(v["real_time_factor"])))
    rows.sort()
    if not rows:
        raise RuntimeError(f"no status of the sim in {bag}")
    before = max((r for r in rows if r[0] <= at_tick), default=rows[0])
    last = rows[-1]

    def pct(a: tuple[int, ...], b: tuple[int, ...]) -> float:
        return 100.0 * (b[1] - a[1]) / max(b[0] - a[0], 1)

    def rtf(part: list[tuple[int, int, float]]) -> float:
        return float(np.median([r[2] for r in part])) if part else float("nan")
    started = [r for r in rows if r[0] > 0]
    after = [before] + [r for r in rows if r[0] > before[0]]
    bins = [pct(a, b) for a, b in zip(after, after[1:]) if b[0] > a[0]]
    return (pct((0, 0), before), pct(before, last),
            rtf([r for r in started if r[0] <= at_tick]),
            rtf([r for r in started if r[0] > at_tick]), bins)


#: Wall s after the (possible) kill over which the sim's CPU time is taken: the lease.
CPU_WINDOW = 5.0


def run(args: argparse.Namespace, switches: int, domain: int, log_dir: Path,
        kill_idle: float | None = None, kill: bool = True) -> dict:
    """One realtime run; the sim's figures and the lost ticks of each switch (with
    ``kill_idle``: the idle controller is killed that many wall s after tick 0, unless not
    ``kill``; either way the sim's CPU time over the next :data:`CPU_WINDOW` s is taken)."""
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters

    from hexapod_bringup.cmd_graph import GraphProcesses
    from hexapod_common.core.switch_channel import ChannelError, request

    duration = args.every * (switches + 1) if switches else args.duration
    g = GraphProcesses(log_dir, env={"ROS_DOMAIN_ID": str(domain)},
                       overrides=(f"sim.dt:={args.dt}", f"sim.control_period:={args.period}",
                                  f"sim.mode:={args.mode}",
                                  *(f"{s.replace('=', ':=', 1)}" for s in args.set)),
                       rt_priority=args.rt_priority)
    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain)
    node = rclpy.create_node("bench_switch", context=ctx, start_parameter_services=False)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    client = node.create_client(SetParameters, "/hexapod_sim/set_parameters")
    clock_ns = [0]
    if kill_idle is not None:
        # Only to learn the sim's tick at the kill: a /clock subscription spun by this
        # process costs the graph ~0.3 ms of executor work per tick, which is not the
        # switch's cost (runs with switches do not subscribe).
        from rosgraph_msgs.msg import Clock

        def on_clock(msg: Clock) -> None:
            clock_ns[0] = msg.clock.sec * 1_000_000_000 + msg.clock.nanosec
        node.create_subscription(Clock, "/clock", on_clock, 10)
    try:
        g.start("metrics", f"bag_path:={log_dir / 'bag'}")
        for name in ("trajectory_generator", "pd_p_controller", "pd_pf_controller"):
            g.start(name)
        g.start("hexapod_sim", "stop_at_end:=true", f"run.duration:={duration}",
                f"wait_for:={ALL}")
        # The service first (it exists before tick 0): its discovery can take a second,
        # which must not delay the switch schedule behind the run.
        assert client.wait_for_service(timeout_sec=60), "no /hexapod_sim/set_parameters"
        g.wait_log("hexapod_sim", f"{args.mode} mode", timeout=180)
        start = time.monotonic()
        kill_tick = None
        if kill_idle is not None:
            while time.monotonic() < start + kill_idle:
                ex.spin_once(timeout_sec=0.01)
            cpu0, at_kill = g.cpu_seconds("hexapod_sim"), time.monotonic()
            if kill:
                g.kill("pd_p_controller")  # pd_pf is in charge: pd_p is idle
            kill_tick = int(round(clock_ns[0] * 1e-9 / args.period))  # the sim's, at the kill
            gone = None
            while time.monotonic() < at_kill + CPU_WINDOW:
                ex.spin_once(timeout_sec=0.01)
                if kill and gone is None and "pd_p_controller" not in node.get_node_names():
                    gone = time.monotonic() - at_kill
            cpu = (g.cpu_seconds("hexapod_sim") - cpu0) / (time.monotonic() - at_kill)
        target = "pd_p"
        for i in range(switches):
            due = start + (i + 1) * args.every
            time.sleep(max(0.0, due - time.monotonic()))  # the bench process sleeps between
            if args.via == "tool":
                if g.procs["hexapod_sim"].poll() is not None:
                    break  # the run is over: the tool calls were slower than --every
                done = subprocess.run([str(ROOT / "scripts" / "switch_controller.sh"), target],
                                      env={**os.environ, "ROS_DOMAIN_ID": str(domain)},
                                      capture_output=True, text=True, timeout=60)
                if done.returncode and g.procs["hexapod_sim"].poll() is None:
                    raise RuntimeError(f"switch_controller.sh {target}: {done.stderr.strip()}"
                                       f"\n--- the sim's log:\n{g.log('hexapod_sim')[-3000:]}")
            elif args.via == "channel":
                if g.procs["hexapod_sim"].poll() is not None:
                    break
                try:
                    answer = request(f"switch {target}", domain, 30)
                except ChannelError:
                    answer = "no answer"
                if g.procs["hexapod_sim"].poll() is not None:
                    break  # the run ended meanwhile
                if answer is None or not answer.startswith("ok"):
                    raise RuntimeError(f"switch {target} through the sim's channel: {answer}")
            else:
                value = ParameterValue(type=ParameterType.PARAMETER_STRING,
                                       string_value=target)
                future = client.call_async(SetParameters.Request(
                    parameters=[Parameter(name="run.controller", value=value)]))
                ex.spin_until_future_complete(future, timeout_sec=10)
            target = "pd_pf" if target == "pd_p" else "pd_p"
        g.wait_exit("hexapod_sim", duration * 20 + 120)
    finally:
        g.stop_all(order=("hexapod_sim", "trajectory_generator", "pd_p_controller",
                          "pd_pf_controller", "metrics"))
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
    m = SUMMARY.search(g.log("hexapod_sim"))
    if m is None:
        raise RuntimeError(f"no summary in {log_dir / 'hexapod_sim.log'}")
    ticks, missed, late, on_time = (int(x) for x in m.groups())
    period_ns = int(round(args.period * 1e9))
    # Without switches: the same windows at the same schedule, as the baseline.
    at = ([int(k) for k in SWITCHED.findall(g.log("hexapod_sim"))] if switches else
          [int(round(i * args.every / args.period)) for i in range(1, int(duration / args.every))])
    lost, recorded, expected = lost_ticks(log_dir / "bag", period_ns, at)
    out = {"ticks": ticks, "missed": missed, "late": late, "on_time": on_time,
           "switches": len(at), "lost": lost, "recorded": recorded, "expected": expected}
    if kill_tick is not None:
        out["split"] = on_time_split(log_dir / "bag", kill_tick)
        out["kill_tick"] = kill_tick
        out["cpu"], out["gone"] = cpu, gone
    return out


def main() -> int:
    reexec_in_env(__file__)
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--switches", type=int, default=50)
    ap.add_argument("--every", type=float, default=0.2, help="simulated s between switches")
    ap.add_argument("--period", type=float, default=0.001, help="control period (s)")
    ap.add_argument("--dt", type=float, default=1e-4, help="physics step (s)")
    ap.add_argument("--duration", type=float, default=10.0, help="s of the run without switches")
    ap.add_argument("--hog", action="store_true", help="one CPU hog beside the graph")
    ap.add_argument("--rt-priority", type=int, default=20, dest="rt_priority",
                    help="SCHED_FIFO priority of the control path, as run_graph.sh --mode "
                    "realtime sets it (0 = normal scheduling)")
    ap.add_argument("--via", choices=("service", "tool", "channel"), default="service",
                    help="how to switch: the sim's set_parameters service from this process "
                    "(default), scripts/switch_controller.sh (a new process per switch), or "
                    "the sim's local switch channel from this process (the path of "
                    "`hexapod switch`, without a process per switch)")
    ap.add_argument("--mode", choices=["realtime", "lockstep"], default="realtime",
                    help="graph mode (lockstep: compare real-time factors)")
    ap.add_argument("--no-baseline", action="store_true", help="skip the run without switches")
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                    help="a parameter for every node, e.g. pd_pf.force_loop=drive")
    ap.add_argument("--keep", type=Path, metavar="DIR",
                    help="keep each run's logs and bag in DIR/run0, DIR/run1 (default: a "
                    "temporary directory, removed)")
    ap.add_argument("--kill-idle", type=float, metavar="S",
                    help="compare runs without switches, one with the idle controller killed "
                    "S wall s in")
    args = ap.parse_args()
    hog = None
    if args.hog:
        hog = multiprocessing.Process(target=_hog, daemon=True)
        hog.start()
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.2f}"
          f"{', one CPU hog' if hog else ''}; {args.mode} mode, {1 / args.period:g} Hz, "
          f"control path under SCHED_FIFO {args.rt_priority} (0 = normal scheduling); "
          f"switching through {VIA[args.via]}")
    base = 170 + os.getpid() % 60
    if args.kill_idle is not None:
        with _work_dir(args.keep) as tmp:
            base_run = run(args, 0, base % 101 + 1, Path(tmp) / "run0",
                           kill_idle=args.kill_idle, kill=False)
            killed = run(args, 0, (base + 1) % 101 + 1, Path(tmp) / "run1",
                         kill_idle=args.kill_idle)
            at = killed["kill_tick"]
            rows = (("no kill", base_run, on_time_split(Path(tmp) / "run0" / "bag", at)),
                    ("idle killed", killed, killed["split"]))
            for label, r, (b, a, rb, ra, bins) in rows:
                print(f"{label}: {r['ticks']} ticks, {r['missed']} missed; before / after tick "
                      f"{at} (the kill, {args.kill_idle:g} wall s in): on time {b:.2f} % / "
                      f"{a:.2f} %, real-time factor (median of the sim's statuses) "
                      f"{rb:.3f} / {ra:.3f}; the sim's CPU use over the {CPU_WINDOW:g} s "
                      f"from then {100 * r['cpu']:.0f} %" + (
                          "" if r is base_run else
                          "; the killed controller left this process's view of the graph "
                          + (f"after more than {CPU_WINDOW:g} s" if r["gone"] is None
                             else f"{r['gone']:.2f} s after the kill"))
                      + "; on time per 0.5 s status interval of the sim from the kill: "
                      + " ".join(f"{x:.1f}" for x in bins) + " %", flush=True)
        print(f"load average after: {os.getloadavg()[0]:.2f}")
        return 0
    try:
        with _work_dir(args.keep) as tmp:
            runs = [("switching", args.switches)]
            if not args.no_baseline:
                runs.insert(0, ("no switch", 0))
            for i, (label, n) in enumerate(runs):
                r = run(args, n, (base + i) % 101 + 1, Path(tmp) / f"run{i}")
                pct = 100.0 * r["on_time"] / max(r["ticks"], 1)
                line = (f"{label}: {r['ticks']} ticks, {pct:.2f} % on time, missed "
                        f"{r['missed']}, late {r['late']}; bag: {r['recorded']} of "
                        f"{r['expected']} states")
                bad = sum(1 for x in r["lost"] if x)
                if n:
                    line += (f"; switches {r['switches']} of {n}, switches with a lost tick: "
                             f"{bad} of {r['switches']} (lost ticks per switch {r['lost']})")
                else:
                    line += (f"; baseline: {bad} of {r['switches']} windows of 5 ticks at the "
                             f"switch schedule have an unanswered tick")
                print(line, flush=True)
    finally:
        if hog is not None:
            hog.terminate()
            hog.join()
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
