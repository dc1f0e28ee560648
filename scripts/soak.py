#!/usr/bin/env python3
"""Soak test R6 (quality.md "Reliability"): 10 simulated minutes in lockstep, all five nodes,
recording on, a controller switch every 10 simulated seconds through the sim's parameter
service (what `hexapod switch` does). Prints the lost ticks (ticks missing from the bag),
the lockstep timeouts (missed ticks), the switches, and the resident-memory growth of each
node between the first and the last sample (targets: 0 lost, 0 timeouts, < 50 MB growth).

Usage: scripts/soak.py [--duration 600] [--switch-every 10] [--keep DIR]
(run through `scripts/env.sh`, or it re-executes itself inside it; on ROS_DOMAIN_ID if set,
else on one drawn from its pid). Exit code 0 if every
target is met, 1 otherwise.
"""
from __future__ import annotations

import argparse
import os
import re
import sys
import tempfile
import time
from pathlib import Path
from project_env import reexec_in_env

ROOT = Path(__file__).resolve().parent.parent
NODES = ("hexapod_sim", "trajectory_generator", "pd_p_controller", "pd_pf_controller",
         "metrics")


class Client:
    """An rclpy node on the graph's domain: reads /hexapod/status, switches controllers."""

    def __init__(self, domain: int) -> None:
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor

        from hexapod_common.runtime import conversions as C

        self.ctx = Context()
        rclpy.init(context=self.ctx, domain_id=domain)
        self.node = rclpy.create_node(f"soak_{os.getpid()}", context=self.ctx,
                                      start_parameter_services=False)
        self.ex = SingleThreadedExecutor(context=self.ctx)
        self.ex.add_node(self.node)
        self.status: dict[str, str] = {}

        def on_status(msg: DiagnosticArray) -> None:
            for s in C.statuses(msg):
                if s.name == "hexapod_sim":
                    self.status = dict(s.values)

        self.node.create_subscription(DiagnosticArray, "/hexapod/status", on_status, 10)

    def spin(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.ex.spin_once(timeout_sec=max(0.0, end - time.monotonic()))

    def switch(self, controller: str) -> bool:
        from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
        from rcl_interfaces.srv import SetParameters

        client = self.node.create_client(SetParameters, "/hexapod_sim/set_parameters")
        client.wait_for_service(timeout_sec=10)
        value = ParameterValue(type=ParameterType.PARAMETER_STRING, string_value=controller)
        future = client.call_async(SetParameters.Request(
            parameters=[Parameter(name="run.controller", value=value)]))
        self.ex.spin_until_future_complete(future, timeout_sec=10)
        self.node.destroy_client(client)
        return bool(future.done() and future.result().results[0].successful)

    def close(self) -> None:
        import rclpy

        self.node.destroy_node()
        rclpy.try_shutdown(context=self.ctx)


def main() -> int:
    reexec_in_env(__file__)
    from hexapod_bringup.cmd_graph import GraphProcesses
    from hexapod_metrics.bag import open_bag, read_joint_state_arrays
    from hexapod_common.core import topics as T

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=600.0, help="simulated seconds")
    ap.add_argument("--switch-every", type=float, default=10.0, help="simulated seconds")
    ap.add_argument("--keep", help="keep the bag and logs in this directory")
    args = ap.parse_args()
    work = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="soak_"))
    work.mkdir(parents=True, exist_ok=True)
    domain = int(os.environ.get("ROS_DOMAIN_ID") or 1 + os.getpid() % 101)
    g = GraphProcesses(work / "logs", env={"ROS_DOMAIN_ID": str(domain)})
    client = Client(domain)
    rss: dict[str, list[float]] = {n: [] for n in NODES}
    switches = refused = 0
    t0 = time.monotonic()
    try:
        g.start("metrics", f"bag_path:={work / 'bag'}")
        for n in ("trajectory_generator", "pd_p_controller", "pd_pf_controller"):
            g.start(n)
        g.start("hexapod_sim", "stop_at_end:=true", f"run.duration:={args.duration}")
        g.wait_log("hexapod_sim", "lockstep mode", timeout=120)
        next_switch, target = args.switch_every, "pd_p"
        # RSS growth is measured from here: by 30 s the readers' replay windows
        # (msg_auth.REPLAY_WINDOW, 65536 messages per sender) have filled at 10 kHz
        warmup = min(30.0, args.duration / 10)
        last_print = 0.0
        while g.procs["hexapod_sim"].poll() is None:
            client.spin(0.2)
            sim_t = float(client.status.get("sim_time", 0.0))
            if sim_t >= next_switch and sim_t < args.duration - 0.5:
                if client.switch(target):
                    switches += 1
                else:
                    refused += 1
                target = "pd_pf" if target == "pd_p" else "pd_p"
                next_switch += args.switch_every
            now = {}
            for n in NODES:
                try:
                    v = g.rss_mb(n)
                except (OSError, KeyError):
                    continue
                if v == v:  # NaN once the process has ended
                    now[n] = v
            if sim_t >= warmup:
                for n, v in now.items():
                    rss[n] = [rss[n][0] if rss[n] else v, v]  # first and last sample
            if sim_t - last_print >= 60 or not last_print:
                last_print = max(sim_t, 1e-9)
                print(f"sim time {sim_t:7.1f} s, wall {time.monotonic() - t0:6.1f} s, "
                      f"switches {switches}, RSS MB: "
                      + ", ".join(f"{n} {v:.0f}" for n, v in now.items()), flush=True)
        code = g.wait_exit("hexapod_sim", 60)
        log = g.log("hexapod_sim")
    finally:
        client.close()
        g.stop_all(order=("trajectory_generator", "pd_p_controller", "pd_pf_controller",
                          "metrics"))
    m = re.search(r"stopped at tick (\d+) .*?: (\d+) missed, (\d+) late.*?(\d+) switches", log)
    if code != 0 or m is None:
        print(f"soak: the sim failed (exit {code}); see {work / 'logs'}")
        return 1
    ticks, missed, late, sim_switches = (int(x) for x in m.groups())
    with open_bag(work / "bag") as bag:
        js = read_joint_state_arrays(bag, T.JOINT_STATES)
        cmd = read_joint_state_arrays(bag, T.JOINT_COMMANDS)
        truncated = bag.truncated
    from hexapod_common.core.params import load_params

    period_ns = int(round(load_params().sim.control_period * 1e9))  # the graph's params file
    present = set((js.stamps // period_ns).tolist())
    lost = (ticks + 1) - len(present & set(range(ticks + 1)))
    cmd_ticks = set((cmd.stamps // period_ns).tolist())
    lost_cmd = ticks - len(cmd_ticks & set(range(ticks)))
    growth = {n: (v[-1] - v[0]) if len(v) > 1 else float("nan") for n, v in rss.items()}
    print(f"R6 soak: {args.duration:g} simulated s ({ticks} ticks) in "
          f"{time.monotonic() - t0:.0f} s wall, lockstep, recording on")
    print(f"  switches: {sim_switches} done by the sim ({switches} requested, {refused} refused)")
    print(f"  lost ticks: {lost} states and {lost_cmd} commands missing from the bag "
          f"(bag {'truncated' if truncated else 'closed cleanly'})")
    print(f"  lockstep timeouts (missed ticks): {missed}; late commands: {late}")
    print(f"  RSS growth (MB, from t = {min(30.0, args.duration / 10):g} s to the end): "
          + ", ".join(f"{n} {growth[n]:+.1f}" for n in NODES))
    ok = lost == 0 and lost_cmd == 0 and missed == 0 and all(
        g_ < 50 for g_ in growth.values()) and sim_switches == switches
    print(f"  targets (0 lost, 0 timeouts, growth < 50 MB): {'met' if ok else 'NOT met'}")
    if not args.keep:
        import shutil

        shutil.rmtree(work, ignore_errors=True)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
