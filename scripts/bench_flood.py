#!/usr/bin/env python3
"""S7 (quality.md): what a process flooding the tick topics costs a lockstep run.

Runs the lockstep graph (all five nodes, recording and authentication on) for --duration
simulated seconds at --rate Hz, in rounds: without a flood, then with a flooding process
on the graph's ROS_DOMAIN_ID (not one of the graph's nodes, without the run's key) from
outside the run's DDS partition and from inside it (--attacker). The flood (--flood):

* ``spray`` (default): every /hexapod/joint_states message copied onto each of the other
  JointState topics of the graph (foot forces, hip states, references, commands), once
  with each --qos profile (reliable, best effort: ``both``, the default, sends 8 copies a
  tick);
* ``mirror``: every message of the tick topics republished, unchanged, on its own topic.

The graph keeps its tick topics in a partition of the run's own (dds_profile.py): from
outside it, nothing reaches the graph's readers; from inside (an attacker who read the
partition's name off the discovery traffic), every copy reaches every reader of its topic
and is refused there in Python by its trailer (replayed, moved or forged). From outside
the partition the flood reads no tick message, so it has nothing to copy: what it costs is
its presence on the domain.

Prints each run's wall time (tick 0 to the last tick, as the sim reports it), what the
flood sent and what the graph's nodes dropped, and the ratio of the median wall times
with / without the flood (target <= 1.5).

Usage: scripts/bench_flood.py [--rate 1000] [--duration 3] [--pairs 3]
       [--flood spray|mirror] [--attacker outsider|insider|both]
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


def flood(kind: str, qos_names: list[str], out: Path) -> int:
    """The flooding process (until SIGINT/SIGTERM; writes the number of messages it sent to
    ``out``): ``mirror`` republishes every message of the tick topics on its own topic;
    ``spray`` copies every /hexapod/joint_states onto each of the other JointState topics of
    the graph, once per QoS of ``qos_names`` (8 a tick with both). Outside the run's DDS
    partition it reads nothing, so has nothing to copy."""
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
    node = Node("flood", start_parameter_services=False)
    # Woken at most every 0.5 ms: it keeps up with the tick rate without a wake-up per
    # message (what a flood that means to cost the graph, not itself, would do).
    loop = HotLoop(node, batch_interval=0.0005)
    sent = [0]
    topics = (T.JOINT_STATES, T.FOOT_FORCES, T.HIP_STATES, T.REFERENCE, T.JOINT_COMMANDS)

    def writers(topic: str) -> list:
        out = []
        for name in qos_names:
            rel = (ReliabilityPolicy.RELIABLE if name == "reliable"
                   else ReliabilityPolicy.BEST_EFFORT)
            # the topic's durability, so that its transient-local readers match it too
            out.append(node.create_publisher(JointState, topic, QoSProfile(
                depth=100, reliability=rel,
                durability=C.TOPIC_QOS[topic].publisher().durability)))
        return out

    # Its own copies come back to its subscriptions (rclpy cannot ignore local
    # publications): each is recognised by its bytes and not copied again.
    own: Counter[bytes] = Counter()

    def send(data: bytes, pubs: list, back: bool = False) -> None:
        """Publish ``data`` with each of ``pubs`` (``back``: on a topic it reads too)."""
        for pub in pubs:
            pub.publish(data)
        sent[0] += len(pubs)
        if back:
            if len(own) > 100000:  # copies that never came back (best effort)
                own.clear()
            own[data] += len(pubs)

    def mine(data: bytes) -> bool:
        if own[data]:
            own[data] -= 1
            if not own[data]:
                del own[data]
            return True
        return False

    if kind == "mirror":
        for topic in topics:
            pubs = writers(topic)

            def copy(data: bytes, pubs: list = pubs) -> None:
                if not mine(data):
                    send(data, pubs, back=True)
            loop.subscribe(JointState, topic, copy,
                           C.TOPIC_QOS[topic].subscriber(C.CONTROL_DEPTH))
    else:
        sprayed = [w for t in topics[1:] for w in writers(t)]

        def spray(data: bytes) -> None:
            send(data, sprayed)
        loop.subscribe(JointState, T.JOINT_STATES, spray,
                       C.TOPIC_QOS[T.JOINT_STATES].subscriber(C.CONTROL_DEPTH))
    install_stop_signals(loop)
    print("flood: ready", flush=True)
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


def attacker_env(env: dict[str, str], attacker: str) -> dict[str, str]:
    """The flooding process's environment: an ``insider`` loads the run's DDS profile (as
    one who read the partition's name off the discovery traffic would), an ``outsider``
    does not; neither holds the run's key."""
    from hexapod_common.core.msg_auth import KEY_ENV

    drop = {KEY_ENV} | ({"FASTRTPS_DEFAULT_PROFILES_FILE"} if attacker == "outsider" else set())
    return {k: v for k, v in env.items() if k not in drop}


def run(rate: float, duration: float, domain: int, log_dir: Path, qos: str | None,
        kind: str = "spray", attacker: str = "outsider") -> dict:
    """One lockstep run, with a flood (``kind``, ``attacker``) under ``qos`` (None:
    without)."""
    from hexapod_bringup.cmd_graph import GraphProcesses

    g = GraphProcesses(log_dir, env={"ROS_DOMAIN_ID": str(domain)},
                       overrides=(f"sim.control_period:={1.0 / rate!r}",))
    flood_proc = None
    count = log_dir / "flood_sent.txt"
    try:
        if qos is not None:
            names = ["reliable", "best_effort"] if qos == "both" else [qos]
            flood_proc = subprocess.Popen(
                [sys.executable, __file__, "--flood-node", kind, "--qos-names",
                 ",".join(names), "--out", str(count)],
                env=attacker_env(g.env, attacker), stdout=subprocess.PIPE, text=True)
            assert flood_proc.stdout is not None
            if flood_proc.stdout.readline().strip() != "flood: ready":
                raise RuntimeError("the flooding process did not start")
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
        if flood_proc is not None:
            flood_proc.send_signal(signal.SIGINT)
            try:
                flood_proc.wait(30)
            except subprocess.TimeoutExpired:
                flood_proc.kill()
                flood_proc.wait()
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
    ap.add_argument("--pairs", type=int, default=3,
                    help="rounds of a run without and runs with the flood")
    ap.add_argument("--flood", choices=("spray", "mirror"), default="spray",
                    help="spray: every state copied onto the 4 other JointState topics "
                         "per QoS (default); mirror: every tick message republished")
    ap.add_argument("--attacker", choices=("outsider", "insider", "both"), default="both",
                    help="outsider: without the run's DDS profile; insider: with it (knows "
                         "the partition from the discovery traffic); both (default)")
    ap.add_argument("--qos", choices=("reliable", "best_effort", "both"), default="both",
                    help="the flood's publishers (default both: 8 copies a tick)")
    ap.add_argument("--flood-node", help=argparse.SUPPRESS)
    ap.add_argument("--qos-names", help=argparse.SUPPRESS)
    ap.add_argument("--out", type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.flood_node:
        return flood(args.flood_node, args.qos_names.split(","), args.out)
    if args.rate <= 0 or args.duration <= 0 or args.pairs < 1:
        ap.error("--rate and --duration must be > 0 and --pairs >= 1")
    attackers = ["outsider", "insider"] if args.attacker == "both" else [args.attacker]
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.2f}; lockstep "
          f"at {args.rate:g} Hz for {args.duration:g} simulated s, recording and "
          f"authentication on; flood '{args.flood}' publishing with {args.qos} QoS, from "
          f"{' and '.join(attackers)} the run's DDS partition", flush=True)
    cost = rejection_cost()
    print("refusal on raw bytes by the input guard, us per message (median of 20 x 1000; "
          "target <= 5): " + ", ".join(f"{k} {v:.2f}" for k, v in cost.items()), flush=True)
    base = 120 + os.getpid() % 50
    walls: dict[str | None, list[float]] = {None: [], **{a: [] for a in attackers}}
    with tempfile.TemporaryDirectory(prefix="bench_flood_") as tmp:
        for i in range(args.pairs):
            for j, who in enumerate([None] + attackers):
                r = run(args.rate, args.duration, (base + 3 * i + j) % 101 + 1,
                        Path(tmp) / f"run{i}_{j}", args.qos if who else None, args.flood,
                        who or "outsider")
                walls[who].append(r["wall"])
                drops = ", ".join(f"{n} {d}" for n, d in r["dropped"].items())
                print(f"round {i + 1} {'without a flood' if who is None else 'flood from ' + who}"
                      f": {r['ticks']} ticks, wall {r['wall']:.2f} s, real-time factor "
                      f"{r['rtf']:.3f}; messages sent {r['sent']}; dropped by the graph's "
                      f"nodes: {drops}", flush=True)
    a = statistics.median(walls[None])
    for who in attackers:
        b = statistics.median(walls[who])
        print(f"S7 wall time with a flood from {who} / without (median of {args.pairs} "
              f"each): {b:.2f} / {a:.2f} s = {b / a:.2f}  (target <= 1.5)")
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
