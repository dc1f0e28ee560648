#!/usr/bin/env python3
"""S7 (quality.md): what a process mirroring the tick topics costs a lockstep run.

Runs the lockstep graph (all five nodes, recording and authentication on) for --duration
simulated seconds at --rate Hz, alternately without and with a *mirror*: a separate
process on the graph's ROS_DOMAIN_ID, not one of the graph's nodes, that takes every
message of the tick topics (joint states, foot forces, hip states, references, commands)
and publishes it again, unchanged, on the same topic (a replayed copy of a genuine, signed
message) at the rate it arrives, with --qos reliable or best_effort (the two common
profiles, with the topic's durability; ``both`` publishes every copy once with each; a
best-effort writer matches none of the graph's readers, which are all reliable). Every copy
reaches every reader of its topic and must be refused there (replayed: the graph's nodes
check the trailer before anything else).

Prints each run's wall time (tick 0 to the last tick, as the sim reports it), what the
mirror sent and what the graph's nodes dropped, and the ratio of the median wall times
with / without the mirror (target <= 1.5).

Usage: scripts/bench_flood.py [--rate 1000] [--duration 3] [--pairs 2]
       [--qos reliable|best_effort|both]
(run through `scripts/env.sh`, or it re-executes itself inside it).
"""
from __future__ import annotations

import argparse
from collections import Counter
import os
import re
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from project_env import reexec_in_env

SUMMARY = re.compile(r"stopped at tick (\d+) .*wall ([\d.]+) s, real-time factor ([\d.]+)")
NODES = ("metrics", "trajectory_generator", "pd_p_controller", "pd_pf_controller")
DROPPED = re.compile(r"dropped (\d+) messages")


def mirror(qos_names: list[str], out: Path) -> int:
    """The mirror process: republish every message of the tick topics until SIGINT/SIGTERM;
    writes the number of copies sent to ``out``."""
    import rclpy
    from rclpy.node import Node
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from rclpy.signals import SignalHandlerOptions
    from sensor_msgs.msg import JointState

    from hexapod_common.core import topics as T
    from hexapod_common.runtime import conversions as C
    from hexapod_common.runtime.hot_loop import (HotLoop, configure_middleware,
                                                 install_stop_signals)

    configure_middleware()
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node = Node("mirror", start_parameter_services=False)
    # Woken at most every 0.5 ms: it keeps up with the tick rate without a wake-up per
    # message (what a flood that means to cost the graph, not itself, would do).
    loop = HotLoop(node, batch_interval=0.0005)
    sent = [0]
    # Its own copies come back to its subscriptions (rclpy cannot ignore local
    # publications): each is recognised by its bytes and not copied again.
    own: Counter[bytes] = Counter()
    for topic in (T.JOINT_STATES, T.FOOT_FORCES, T.HIP_STATES, T.REFERENCE, T.JOINT_COMMANDS):
        pubs = []
        for name in qos_names:
            rel = (ReliabilityPolicy.RELIABLE if name == "reliable"
                   else ReliabilityPolicy.BEST_EFFORT)
            # the topic's durability, so that its transient-local readers match it too
            pubs.append(node.create_publisher(JointState, topic, QoSProfile(
                depth=100, reliability=rel,
                durability=C.TOPIC_QOS[topic].publisher().durability)))

        def copy(data: bytes, pubs: list = pubs) -> None:
            if own[data]:
                own[data] -= 1
                if not own[data]:
                    del own[data]
                return
            if len(own) > 100000:  # copies that never came back (best effort)
                own.clear()
            for p in pubs:
                p.publish(data)
            own[data] += len(pubs)
            sent[0] += len(pubs)
        loop.subscribe(JointState, topic, copy,
                       C.TOPIC_QOS[topic].subscriber(C.CONTROL_DEPTH))
    install_stop_signals(loop)
    print("mirror: ready", flush=True)
    try:
        loop.spin()
    finally:
        out.write_text(str(sent[0]))
        loop.destroy()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


def rejection_cost(batches: int = 20, per_batch: int = 1000) -> dict[str, float]:
    """Microseconds of CPU the input guard takes to refuse one message on raw bytes (median
    of ``batches`` batches): a replayed copy of an accepted state, a forged one (a valid
    layout signed with another key) and a message moved from another topic."""
    import numpy as np
    import rclpy
    from rclpy.context import Context

    from hexapod_common.core import topics as T
    from hexapod_common.core.msg_auth import (AUTH_ENV, KEY_ENV, Signer, new_key_file,
                                              read_key_file)
    from hexapod_common.runtime import conversions as C
    from hexapod_common.runtime.input_guard import InputGuard

    class Quiet:
        def warning(self, message: str) -> None:
            pass
        info = error = debug = warning

    ctx = Context()
    rclpy.init(context=ctx, domain_id=200 + os.getpid() % 30)
    saved = {k: os.environ.get(k) for k in (KEY_ENV, AUTH_ENV)}
    try:
        node = rclpy.create_node("bench_flood_guard", context=ctx,
                                 start_parameter_services=False)
        with tempfile.TemporaryDirectory(prefix="bench_flood_key_") as tmp:
            path = new_key_file(tmp)
            os.environ[KEY_ENV], os.environ[AUTH_ENV] = str(path), "on"
            key = read_key_file(path)
            guard = InputGuard(node, Quiet())
        for k, v in saved.items():  # the graphs get keys of their own
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
        z = np.zeros(12)
        period = 1_000_000

        def state(k: int) -> bytes:
            return C.CODECS[T.JOINT_STATES].encode(k * period, "pd_pf", z, z, z)
        genuine = Signer(key, T.JOINT_STATES).sign(state(1))
        assert guard.joint_state(T.JOINT_STATES, genuine, period) is not None
        forger = Signer(os.urandom(32), T.JOINT_STATES)
        forged = [forger.sign(state(k)) for k in range(per_batch)]
        moved_signer = Signer(key, T.FOOT_FORCES)
        moved = [moved_signer.sign(C.CODECS[T.FOOT_FORCES].encode(k * period, "", z, z, z))
                 for k in range(per_batch)]
        kinds = {"replayed": [genuine] * per_batch, "forged": forged, "moved": moved}
        out = {}
        decoded = guard.decoded
        for name, msgs in kinds.items():
            times = []
            for _ in range(batches):  # CPU time: the machine may be shared
                t0 = time.thread_time()
                for data in msgs:
                    guard.joint_state(T.JOINT_STATES, data, period)
                times.append((time.thread_time() - t0) / per_batch * 1e6)
            out[name] = statistics.median(times)
        assert guard.decoded == decoded, "a refused message was decoded"
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)
    return out


def run(rate: float, duration: float, domain: int, log_dir: Path, qos: str | None) -> dict:
    """One lockstep run, with a mirror under ``qos`` (None: without)."""
    from hexapod_bringup.cmd_graph import GraphProcesses

    g = GraphProcesses(log_dir, env={"ROS_DOMAIN_ID": str(domain)},
                       overrides=(f"sim.control_period:={1.0 / rate!r}",))
    mirror_proc = None
    count = log_dir / "mirror_sent.txt"
    try:
        if qos is not None:
            names = ["reliable", "best_effort"] if qos == "both" else [qos]
            mirror_proc = subprocess.Popen(
                [sys.executable, __file__, "--mirror-node", ",".join(names), "--out",
                 str(count)], env=g.env, stdout=subprocess.PIPE, text=True)
            assert mirror_proc.stdout is not None
            if mirror_proc.stdout.readline().strip() != "mirror: ready":
                raise RuntimeError("the mirror did not start")
        g.start("metrics", f"bag_path:={log_dir / 'bag'}")
        for name in NODES[1:]:
            g.start(name)
        wait = ",".join(NODES[1:] + ("metrics",))
        g.start("hexapod_sim", "stop_at_end:=true", f"run.duration:={duration}",
                "sim.mode:=lockstep", f"wait_for:={wait}")
        g.wait_log("hexapod_sim", "real-time factor", timeout=duration * 60 + 120)
        g.wait_exit("hexapod_sim", 60)
    finally:
        g.stop_all(order=NODES[1:] + ("metrics",))
        if mirror_proc is not None:
            mirror_proc.send_signal(signal.SIGINT)
            try:
                mirror_proc.wait(30)
            except subprocess.TimeoutExpired:
                mirror_proc.kill()
                mirror_proc.wait()
    m = SUMMARY.search(g.log("hexapod_sim"))
    if m is None:
        raise RuntimeError(f"no summary in {log_dir / 'hexapod_sim.log'}")
    dropped = {n: sum(int(x) for x in DROPPED.findall(g.log(n))[-1:])
               for n in ("hexapod_sim",) + NODES}
    return {"ticks": int(m.group(1)), "wall": float(m.group(2)), "rtf": float(m.group(3)),
            "sent": int(count.read_text()) if count.exists() else 0, "dropped": dropped}


def main() -> int:
    reexec_in_env(__file__)
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rate", type=float, default=1000.0, help="control rate (Hz)")
    ap.add_argument("--duration", type=float, default=3.0, help="simulated s per run")
    ap.add_argument("--pairs", type=int, default=2, help="runs without / with the mirror")
    ap.add_argument("--qos", choices=("reliable", "best_effort", "both"), default="reliable",
                    help="the mirror's publishers")
    ap.add_argument("--mirror-node", help=argparse.SUPPRESS)
    ap.add_argument("--out", type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.mirror_node:
        return mirror(args.mirror_node.split(","), args.out)
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.2f}; lockstep "
          f"at {args.rate:g} Hz for {args.duration:g} simulated s, recording and "
          f"authentication on; mirror publishing with {args.qos} QoS", flush=True)
    cost = rejection_cost()
    print("refusal on raw bytes by the input guard, us per message (median of 20 x 1000; "
          "target <= 5): " + ", ".join(f"{k} {v:.2f}" for k, v in cost.items()), flush=True)
    base = 120 + os.getpid() % 50
    walls: dict[bool, list[float]] = {False: [], True: []}
    with tempfile.TemporaryDirectory(prefix="bench_flood_") as tmp:
        for i in range(args.pairs):
            for j, with_mirror in enumerate((False, True)):
                r = run(args.rate, args.duration, (base + 2 * i + j) % 101 + 1,
                        Path(tmp) / f"run{i}_{j}", args.qos if with_mirror else None)
                walls[with_mirror].append(r["wall"])
                drops = ", ".join(f"{n} {d}" for n, d in r["dropped"].items())
                print(f"pair {i + 1} {'with' if with_mirror else 'without'} the mirror: "
                      f"{r['ticks']} ticks, wall {r['wall']:.2f} s, real-time factor "
                      f"{r['rtf']:.3f}; copies sent {r['sent']}; dropped by the graph's "
                      f"nodes: {drops}", flush=True)
    a, b = statistics.median(walls[False]), statistics.median(walls[True])
    print(f"S7 wall time with / without the mirror (median of {args.pairs} each): "
          f"{b:.2f} / {a:.2f} s = {b / a:.2f}  (target <= 1.5)")
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
