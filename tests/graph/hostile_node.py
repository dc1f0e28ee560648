"""A hostile process on the graph's ROS_DOMAIN_ID: a rogue that tries to drive the robot, or
a fuzzer that sends malformed messages on every topic the graph subscribes to.

Run as a script (a real, separate node process; not one of the graph's nodes)::

    python hostile_node.py rogue|fuzz --out COUNTS.json [--name NODE] [--seed N] [--sign]
        [--blind]

* ``rogue``: answers every /hexapod/joint_states with its own command (same stamp and
  frame_id, +80 N m on every joint), also a constant stale command at 500 Hz; forges
  joint_states (+0.1 rad) and references (+0.2 rad) with the genuine stamps; announces the
  other controller on /hexapod/active_controller; publishes /clock ahead of the run; and
  replays (unchanged, and later) and tampers with the graph's own signed messages.
* ``fuzz``: random bytes, empty, truncated, wrong-shape messages, NaN values and stamps
  outside the run (1e6 s, negative, off-tick) on every topic, ~400 a second. With
  ``--sign`` (and ``HEXAPOD_KEY_FILE``) every other message carries a valid tag, as if a
  buggy node of the graph sent it: then the message checks, not the authentication, must
  catch it. It never sends a well-formed message in the run's window.

It prints ``hostile: active`` once it has seen the graph's states, and writes what it sent
(per topic and kind) to ``--out`` when stopped (SIGINT/SIGTERM).
"""
from __future__ import annotations

import argparse
import json
import os
import random
import signal
import struct
import sys
from collections import Counter, deque
from typing import Any

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.serialization import deserialize_message, serialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from visualization_msgs.msg import MarkerArray

from hexapod_common.runtime import conversions as C
from hexapod_common.core import topics as T
from hexapod_common.core.labels import in_charge
from hexapod_common.core.msg_auth import TRAILER_BYTES, Signer, run_key
from hexapod_common.core.param_log import RECORD_NAME, ParamRecord

TYPES = {T.JOINT_STATES: JointState, T.FOOT_FORCES: JointState, T.HIP_STATES: JointState,
         T.REFERENCE: JointState, T.JOINT_COMMANDS: JointState, T.ACTIVE_CONTROLLER: String,
         T.STATUS: DiagnosticArray, T.MARKERS: MarkerArray, T.CLOCK: Clock,
         T.PARAMETERS: DiagnosticArray, T.RECORDED: DiagnosticArray}
QOS = {**C.TOPIC_QOS, T.RECORDED: C.RECORDED_QOS}
NS = 1_000_000_000


def _qos(topic: str) -> Any:
    return QOS[topic].subscriber(50)


class Hostile:
    """The rogue or fuzzer node (a plain rclpy node with a standard executor)."""

    def __init__(self, kind: str, name: str, seed: int, sign: bool, blind: bool = False
                 ) -> None:
        self.node = rclpy.create_node(name, start_parameter_services=False)
        self.kind = kind
        self.rng = random.Random(seed)
        self.sent: Counter[str] = Counter()
        self.refused: Counter[str] = Counter()
        self.pubs = {t: self.node.create_publisher(m, t, QOS[t].publisher())
                     for t, m in TYPES.items()}
        # Fast DDS never delivers an empty sample, and a reliable reader then holds back
        # every later sample of that writer (in-order delivery): empty ones get writers
        # of their own, so that they stall nothing but themselves.
        self.empty_pubs = {t: self.node.create_publisher(m, t, QOS[t].publisher())
                           for t, m in TYPES.items()}
        key = run_key() if sign else None
        self.signers = {t: Signer(key, t) for t in TYPES} if key is not None else {}
        self.genuine: dict[str, deque[bytes]] = {t: deque(maxlen=200) for t in TYPES}
        self.mine: set[bytes] = set()
        self.mine_order: deque[bytes] = deque()
        self.active = blind  # blind: at once, without having seen the graph's states
        if blind:
            print("hostile: active", flush=True)
        self.last_state: JointState | None = None
        for t, m in TYPES.items():
            if t != T.CLOCK:
                self.node.create_subscription(m, t, self._make_cb(t), _qos(t), raw=True)
        period = 0.002 if kind == "rogue" else 0.0025
        self.node.create_timer(period, self._tick)

    # ------------------------------------------------------------------ plumbing
    def _make_cb(self, topic: str) -> Any:
        def cb(data: bytes) -> None:
            if data in self.mine:
                return
            try:
                msg = deserialize_message(data, TYPES[topic])  # the trailer is ignored
            except Exception:  # garbage of its own come back (blind: nothing else comes)
                return
            self.genuine[topic].append(data)
            if topic == T.JOINT_STATES:
                self.last_state = msg
                if not self.active:
                    self.active = True
                    print("hostile: active", flush=True)
                if self.kind == "rogue":
                    self._rogue_on_state(msg, data)
            elif topic == T.REFERENCE and self.kind == "rogue" and self.active:
                ref = deserialize_message(data, JointState)
                ref.position = [p + 0.2 for p in ref.position]
                self.send(topic, serialize_message(ref), "forged +0.2 rad")
        return cb

    def send(self, topic: str, data: bytes, kind: str, sign: bool = False) -> None:
        """Publish raw bytes (signed with the run's key if asked and held)."""
        if sign and topic in self.signers:
            data = self.signers[topic].sign(data)
            kind += " (signed)"
        # Fast DDS pads a sample to 4 bytes on the way: the copy that comes back to our own
        # subscription may be longer than what we sent (and must not pass for genuine).
        for copy in {data, data + b"\0" * (-len(data) % 4)}:
            self.mine.add(copy)
            self.mine_order.append(copy)
        while len(self.mine_order) > 10000:
            self.mine.discard(self.mine_order.popleft())
        try:
            (self.pubs if data else self.empty_pubs)[topic].publish(data)
        except Exception:  # noqa: BLE001 - DDS refuses some samples (e.g. bounded types)
            self.refused[f"{topic} {kind}"] += 1
            return
        self.sent[f"{topic} {kind}"] += 1

    # ------------------------------------------------------------------ rogue
    def _command(self, stamp: Any, frame: str, effort: float) -> bytes:
        cmd = JointState(name=list(T.JOINT_NAMES), position=[0.0] * 12, velocity=[0.0] * 12,
                         effort=[effort] * 12)
        cmd.header.stamp = stamp
        cmd.header.frame_id = frame
        return serialize_message(cmd)

    def _rogue_on_state(self, msg: JointState, raw: bytes) -> None:
        stamp, frame = msg.header.stamp, in_charge(msg.header.frame_id)
        self.send(T.JOINT_COMMANDS, self._command(stamp, frame, 80.0), "stamp-copying command")
        fake = JointState(header=msg.header, name=msg.name, velocity=msg.velocity,
                          effort=msg.effort, position=[p + 0.1 for p in msg.position])
        self.send(T.JOINT_STATES, serialize_message(fake), "forged +0.1 rad")
        # The graph's own signed messages: replayed at once, replayed 50 ticks later,
        # and with one value changed (the tag then no longer fits).
        self.send(T.JOINT_STATES, raw, "replayed at once")
        old = self.genuine[T.JOINT_STATES]
        if len(old) > 50:
            self.send(T.JOINT_STATES, old[-50], "replayed 50 ticks later")
        for cmd in list(self.genuine[T.JOINT_COMMANDS])[-1:]:
            self.send(T.JOINT_COMMANDS, cmd, "replayed")
            n = len(cmd) - TRAILER_BYTES - 8
            tampered = cmd[:n] + struct.pack("<d", 80.0) + cmd[n + 8:]
            self.send(T.JOINT_COMMANDS, tampered, "tampered")

    @staticmethod
    def _forged_record(st: JointState) -> bytes:
        """A well-formed, checksummed record that says the sim's ground changed to 5.0."""
        tick = (st.header.stamp.sec * NS + st.header.stamp.nanosec) // 1_000_000
        rec = ParamRecord("hexapod_sim", "change", tick, tick * 1_000_000,
                          {"ground.scale": 5.0})
        status = C.Status(f"{RECORD_NAME}/{rec.node}", "ok", "change", rec.to_map())
        return serialize_message(C.diagnostic_array(rec.stamp_ns, [status]))

    def _rogue_tick(self) -> None:
        st = self.last_state
        if st is None:
            return
        frame = in_charge(st.header.frame_id)
        self.send(T.JOINT_COMMANDS, self._command(st.header.stamp, frame, 80.0),
                  "constant stale command")
        if self.rng.random() < 0.05:
            other = "pd_p" if frame == "pd_pf" else "pd_pf"
            self.send(T.ACTIVE_CONTROLLER, serialize_message(String(data=other)),
                      "forged controller")
            for raw in list(self.genuine[T.ACTIVE_CONTROLLER])[-1:]:
                self.send(T.ACTIVE_CONTROLLER, raw, "replayed")
            self.send(T.PARAMETERS, self._forged_record(st), "forged ground change")
            t = st.header.stamp.sec * NS + st.header.stamp.nanosec + NS // 2
            clock = Clock()
            clock.clock.sec, clock.clock.nanosec = divmod(t, NS)
            self.send(T.CLOCK, serialize_message(clock), "0.5 s ahead")

    # ------------------------------------------------------------------ fuzz
    def _random_bytes(self) -> bytes:
        data = bytes(self.rng.getrandbits(8) for _ in range(self.rng.randrange(1, 700)))
        return b"\x01" + data[1:] if data[:2] == b"\x00\x01" else data

    def _fuzz_tick(self) -> None:
        topic = self.rng.choice(list(TYPES))
        sign = bool(self.signers) and self.rng.random() < 0.5 and topic != T.MARKERS
        kinds = ["random", "empty", "header only", "truncated"]
        if TYPES[topic] is JointState:
            kinds += ["wrong names", "short array", "NaN", "infinity", "stamp 1e6 s",
                      "negative stamp", "off-tick stamp"]
        if topic == T.ACTIVE_CONTROLLER:
            kinds += ["unknown controller", "not UTF-8"]
        if topic == T.JOINT_COMMANDS:
            kinds += ["negative drive gain", "drive gains, 23 entries"]
        kind = self.rng.choice(kinds)
        data = self._fuzz_message(topic, kind)
        if data is not None:
            self.send(topic, data, kind, sign)

    def _genuine_payload(self, topic: str) -> bytes | None:
        got = self.genuine[topic]
        if not got:
            return None
        return got[-1][:-TRAILER_BYTES] if self.signers or os.environ.get(
            "HEXAPOD_AUTH", "on") != "off" else got[-1]

    def _fuzz_message(self, topic: str, kind: str) -> bytes | None:
        if kind == "random":
            return self._random_bytes()
        if kind == "empty":
            return b""
        if kind == "header only":
            return C.ENCAPSULATION
        payload = self._genuine_payload(topic)
        if kind == "truncated":
            if payload is None or len(payload) < 8:
                return self._random_bytes()
            return payload[:self.rng.randrange(4, len(payload) - 4)]
        if kind == "unknown controller":
            return serialize_message(String(data="pd_x"))
        if kind == "not UTF-8":
            return C.ENCAPSULATION + struct.pack("<I", 4) + b"\xff\xfe\xfd\x00"
        if payload is None:
            return None
        msg = deserialize_message(payload, JointState)
        if kind == "wrong names":
            msg.name = msg.name[:3]
            msg.position, msg.velocity, msg.effort = (list(msg.position[:3]),
                                                      list(msg.velocity[:3]),
                                                      list(msg.effort[:3]))
        elif kind == "short array":
            msg.effort = list(msg.effort[:-1])
        elif kind in ("negative drive gain", "drive gains, 23 entries"):
            msg.name = list(T.DRIVE_COMMAND_NAMES)  # a drive command (docs/controllers.md)
            gains = [1.0] * len(T.JOINT_NAMES)
            if kind == "negative drive gain":
                gains[self.rng.randrange(len(gains))] = -1.0
            msg.position, msg.velocity, msg.effort = (list(msg.position[:12]) + gains,
                                                      list(msg.velocity[:12]) + gains,
                                                      list(msg.effort[:12]) + gains)
            if kind == "drive gains, 23 entries":
                msg.name = msg.name[:-1]
        elif kind in ("NaN", "infinity"):
            bad = float("nan") if kind == "NaN" else float("inf")
            arr = self.rng.choice(("position", "velocity", "effort"))
            values = list(getattr(msg, arr))
            values[self.rng.randrange(len(values))] = bad
            setattr(msg, arr, values)
        elif kind == "stamp 1e6 s":
            msg.header.stamp.sec = 1_000_000
        elif kind == "negative stamp":
            msg.header.stamp.sec = -5
        elif kind == "off-tick stamp":
            msg.header.stamp.nanosec = (msg.header.stamp.nanosec + 123_457) % NS
        return serialize_message(msg)

    def _tick(self) -> None:
        if not self.active:
            return
        if self.kind == "rogue":
            self._rogue_tick()
        else:
            self._fuzz_tick()


def main() -> int:
    """Entry point: run until SIGINT/SIGTERM, then write the counts."""
    ap = argparse.ArgumentParser()
    ap.add_argument("kind", choices=("rogue", "fuzz"))
    ap.add_argument("--out", required=True)
    ap.add_argument("--name", default="")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--sign", action="store_true")
    ap.add_argument("--blind", action="store_true",
                    help="act at once, without waiting to see the graph's states")
    args = ap.parse_args()
    rclpy.init(signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    h = Hostile(args.kind, args.name or f"{args.kind}_node", args.seed, args.sign,
                args.blind)
    stop = []
    signal.signal(signal.SIGINT, lambda *a: stop.append(1))
    signal.signal(signal.SIGTERM, lambda *a: stop.append(1))
    ex = rclpy.executors.SingleThreadedExecutor()
    ex.add_node(h.node)
    try:
        while not stop:
            ex.spin_once(timeout_sec=0.05)
    finally:
        with open(args.out, "w") as f:
            json.dump({"sent": dict(h.sent), "refused": dict(h.refused)}, f, indent=1)
        h.node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    np.seterr(all="ignore")
    sys.exit(main())
