"""Controllers that join a running graph (docs/controllers.md), end to end with real processes.

* the README walk-through: run_graph.sh until Ctrl-C, the example package's node
  (examples/my_controller, built by scripts/setup.sh), `hexapod switch my_controller`, a few
  gait cycles, switch back, Ctrl-C, `hexapod analyze` scores a segment under my_controller
  with the node's own gains;
* a controller written from docs/controllers.md alone (below: rclpy and hashlib, no project
  import), switched in and out, and an unsigned one whose commands are dropped and counted;
* a joined controller that dies in charge: hold, damping fallback, exit code 7.
"""
from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from hexapod_bringup.graph_launcher import EXIT_CODES
from hexapod_common.core import topics as T
from hexapod_common.runtime import conversions as C
from hexapod_common.runtime.dds_profile import partition_of, private_profile
from hexapod_metrics.bag import open_bag

from .bag_checks import recorded_obs
from .conftest import hexapod_cli, sim_summary
from .test_graph_exits import ROOT, Script

EXAMPLE = ROOT / "ros_ws" / "install" / "my_controller" / "lib" / "my_controller" / "my_controller"
CYCLE_S = 1.0  # gait cycle of the base case (s): a segment is scored over its full cycles

#: A controller node written from docs/controllers.md only: the topics, the stamp rule, the
#: frame_id rule and the trailer (BLAKE2b-128 with the key file's 32 bytes, topic NUL payload
#: padding sender sequence). Arguments: the node's name, then the controller's name if it
#: differs (a node that takes a built-in's place: pd_p_controller serves pd_p).
#: UNSIGNED=1: no trailer; ANSWER_ALL=1: it answers every state (a
#: careless node), so its commands reach the sim while another controller is in charge.
SPEC_NODE = r'''
import hashlib, os, secrets, struct, sys
import rclpy
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState

NAME = sys.argv[1]
CONTROLLER = sys.argv[2] if len(sys.argv) > 2 else NAME
UNSIGNED = os.environ.get("UNSIGNED") == "1"
ANSWER_ALL = os.environ.get("ANSWER_ALL") == "1"
TOPIC = "/hexapod/joint_commands"
JOINTS = [f"leg{i}_{j}" for i in range(1, 7) for j in ("hip", "knee")]
KP, KD = {"hip": 100000.0, "knee": 120000.0}, {"hip": 250.0, "knee": 50.0}
KEY = None if UNSIGNED else bytes.fromhex(open(os.environ["HEXAPOD_KEY_FILE"]).read().strip())
SENDER = secrets.token_bytes(8)


def sign(payload, seq):
    pad = -len(payload) % 8
    body = payload + b"\0" * pad
    head = SENDER + struct.pack("<Q", seq | pad << 56)
    tag = hashlib.blake2b(TOPIC.encode() + b"\0" + body + head, key=KEY, digest_size=16)
    return body + head + tag.digest()


class Spec(Node):
    def __init__(self):
        super().__init__(NAME)
        for n in ("kp_hip", "kp_knee"):
            self.declare_parameter(n, KP[n[3:]])
        self.seq, self.refs, self.pending = 0, {}, None
        self.pub = self.create_publisher(JointState, TOPIC, 5000)  # as the doc advises
        self.create_subscription(JointState, "/hexapod/reference", self.on_ref, QoSProfile(
            depth=100, durability=DurabilityPolicy.TRANSIENT_LOCAL))  # as the doc advises
        self.create_subscription(JointState, "/hexapod/joint_states", self.on_state, 100)

    def on_ref(self, m):
        t = (m.header.stamp.sec, m.header.stamp.nanosec)
        self.refs[t] = {n: (p, v) for n, p, v in zip(m.name, m.position, m.velocity)}
        if self.pending is not None and self.key(self.pending) in self.refs:
            self.answer(self.pending)

    def key(self, m):
        return (m.header.stamp.sec, m.header.stamp.nanosec)

    def on_state(self, m):
        if m.header.frame_id.split("/")[0] != CONTROLLER and not ANSWER_ALL:
            return
        self.pending = m
        if self.key(m) in self.refs:
            self.answer(m)

    def answer(self, m):
        self.pending = None
        ref, st = self.refs[self.key(m)], dict(zip(m.name, zip(m.position, m.velocity)))
        eff = [KP[j[5:]] * (ref[j][0] - st[j][0]) + KD[j[5:]] * (ref[j][1] - st[j][1])
               for j in JOINTS]
        cmd = JointState(name=JOINTS, position=[ref[j][0] for j in JOINTS],
                         velocity=[ref[j][1] for j in JOINTS], effort=eff)
        cmd.header.stamp, cmd.header.frame_id = m.header.stamp, CONTROLLER
        data = serialize_message(cmd)
        self.seq += 1
        self.pub.publish(data if UNSIGNED else sign(data, self.seq))
        self.refs = {k: v for k, v in self.refs.items() if k > self.key(m)}


rclpy.init()
node = Spec()
try:
    rclpy.spin(node)
except KeyboardInterrupt:
    pass
finally:
    node.destroy_node()
    rclpy.try_shutdown()
'''


@pytest.fixture
def join_script(tmp_path: Path):
    started: list[Script] = []
    nodes: list[subprocess.Popen[bytes]] = []

    def start(*args: str, lockstep_timeout: float = 5.0) -> Script:
        # Ten times the default wait for a command: on a shared, loaded machine a Python
        # node that idles through every state may lag when it takes over (it answers late
        # rather than never: its queues are deep enough). Paced at half real time: the steps
        # wait for wall-clock things (a node's start, `hexapod switch`), and an unpaced graph
        # would spend both cores meanwhile. (The joining nodes read the references as
        # transient-local readers, as docs/controllers.md advises: a volatile one misses
        # those sent, up to 50 ticks ahead, before it matched; once seen with pacing.)
        s = Script(tmp_path, *args, "--set", f"sim.lockstep_timeout={lockstep_timeout:g}",
                   "--set", "sim.lockstep_max_rtf=0.5")
        started.append(s)
        return s

    start.nodes = nodes  # type: ignore[attr-defined]
    yield start
    for p in nodes:
        if p.poll() is None:
            p.kill()
            p.wait()
    for s in started:
        s.kill_all()


def key_file(s: Script) -> str:
    """The key path run_graph.sh prints for nodes that join."""
    s.wait_for(lambda: "HEXAPOD_KEY_FILE=" in s.stdout(), 120, "the join line")
    m = re.search(r"a controller node joins with ROS_DOMAIN_ID=(\d+) HEXAPOD_KEY_FILE=(\S+)",
                  s.stdout())
    assert m and int(m.group(1)) == s.domain, s.stdout()
    return m.group(2)


def profile_file(s: Script) -> str:
    """The run's Fast DDS profile run_graph.sh prints for nodes that join (it puts the tick
    topics in the run's partition)."""
    s.wait_for(lambda: "FASTRTPS_DEFAULT_PROFILES_FILE=" in s.stdout(), 120, "the join line")
    m = re.search(r"a controller node joins with .* FASTRTPS_DEFAULT_PROFILES_FILE=(\S+)",
                  s.stdout())
    assert m, s.stdout()
    return m.group(1)


def start_node(join_script, s: Script, argv: list[str], name: str,
               **env: str) -> subprocess.Popen[bytes]:
    """A hand-started node on the graph's domain, with the run's DDS profile unless ``env``
    names one (its output in ``<logs>/<name>.out``)."""
    full = {**os.environ, "ROS_DOMAIN_ID": str(s.domain),
            "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
            "FASTRTPS_DEFAULT_PROFILES_FILE": profile_file(s), **env}
    out = open(s.logs / f"{name}.out", "wb")
    p = subprocess.Popen(argv, env=full, stdout=out, stderr=subprocess.STDOUT)
    join_script.nodes.append(p)
    return p


def switch(s: Script, name: str, timeout: float = 60.0) -> str:
    """`hexapod switch name`, again while the sim has not discovered the node yet."""
    end = time.monotonic() + timeout
    while True:
        r = hexapod_cli(s.domain, "switch", name)
        if r.returncode == 0:
            return r.stdout
        assert time.monotonic() < end and ("no controller node" in r.stderr
                                           or "try again" in r.stderr), r.stderr
        time.sleep(0.5)


def sim_time(s: Script) -> float:
    """Sim time (s) the run has reached at least: the end of the newest cycle the recorder
    has scored (its log; polled without starting a process, as `hexapod status` would)."""
    ends = re.findall(r"\[metrics\]: cycle \d+ \[[\d.]+, ([\d.]+)\] s", s.log("metrics"))
    return float(ends[-1]) if ends else 0.0


def switch_tick(s: Script, old: str, new: str) -> float:
    pattern = rf"switched {old} -> {new} at tick \d+ \(t = ([\d.]+) s\)"
    s.wait_for(lambda: re.search(pattern, s.log("hexapod_sim")) is not None, 60,
               f"the switch {old} -> {new}")
    return float(re.search(pattern, s.log("hexapod_sim")).group(1))  # type: ignore[union-attr]


def run_segment(s: Script, name: str, cycles: float = 2.2) -> None:
    """Switch to ``name``, run ``cycles`` gait cycles, switch back to pd_pf."""
    assert f"switching pd_pf -> {name} at the next tick" in switch(s, name)
    t0 = switch_tick(s, "pd_pf", name)
    s.wait_for(lambda: sim_time(s) > t0 + cycles * CYCLE_S, 180, f"{cycles} cycles of {name}")
    assert f"switching {name} -> pd_pf" in switch(s, "pd_pf")
    t1 = switch_tick(s, name, "pd_pf")
    s.wait_for(lambda: sim_time(s) > t1 + 0.1, 60, "ticks after the switch back")


def analyzed_segments(s: Script) -> tuple[str, list[dict]]:
    out = s.bag.parent / "analysis.json"
    r = hexapod_cli(s.domain, "analyze", str(s.bag), "--no-plots", "--json", str(out))
    assert r.returncode == 0, r.stderr
    return r.stdout, [row for row in json.loads(out.read_text()) if row["kind"] == "segment"]


def commands_by_frame(bag: Path) -> dict[str, int]:
    codec = C.CODECS[T.JOINT_COMMANDS]
    out: dict[str, int] = {}
    with open_bag(bag) as b:
        for _, _, data in b.messages([T.JOINT_COMMANDS]):
            frame = codec.decode(bytes(data)).frame_id
            out[frame] = out.get(frame, 0) + 1
    return out


def stop(s: Script, *nodes: subprocess.Popen[bytes]) -> int:
    for p in nodes:
        p.send_signal(signal.SIGINT)
        p.wait(30)
    os.kill(s.proc.pid, signal.SIGINT)  # Ctrl-C: the normal end of a --duration 0 run
    return s.wait(180)


def test_readme_walkthrough_scores_my_controller(join_script):
    assert EXAMPLE.exists(), "scripts/setup.sh builds examples/my_controller"
    s = join_script("--duration", "0", "--no-switch")
    key = key_file(s)
    s.wait_log("hexapod_sim", "lockstep mode")
    node = start_node(join_script, s, [str(EXAMPLE)], "my_controller", HEXAPOD_KEY_FILE=key)

    # a name that is not on the graph: one line, refused, the run goes on
    r = hexapod_cli(s.domain, "switch", "nobody")
    assert r.returncode == 2 and r.stdout == "", r
    assert r.stderr.count("\n") == 1 and "no controller node nobody on ROS_DOMAIN_ID=" \
        in r.stderr, r.stderr

    assert "switching pd_pf -> my_controller at the next tick" in switch(s, "my_controller")
    t0 = switch_tick(s, "pd_pf", "my_controller")
    st = hexapod_cli(s.domain, "status")
    assert st.returncode == 0, st.stderr
    assert "my_controller (node my_controller, in charge)" in st.stdout, st.stdout
    assert "pd_p (node pd_p_controller, active)" in st.stdout, st.stdout
    s.wait_for(lambda: sim_time(s) > t0 + 2.2 * CYCLE_S, 180, "two cycles of my_controller")
    assert "switching my_controller -> pd_pf" in switch(s, "pd_pf")
    t1 = switch_tick(s, "my_controller", "pd_pf")
    s.wait_for(lambda: sim_time(s) > t1 + 0.1, 60, "ticks after the switch back")

    assert stop(s, node) == 0, s.stderr()
    assert "fallback" not in s.stderr()
    frames = commands_by_frame(s.bag)  # the bag names who produced every command
    assert frames.get("my_controller", 0) >= 2 * CYCLE_S / 0.001, frames
    assert set(frames) <= {"pd_pf", "pd_p", "my_controller"}, frames

    text, segments = analyzed_segments(s)
    mine = [g for g in segments if g["controller"] == "my_controller"]
    assert len(mine) == 1 and mine[0]["cycles"] >= 1, segments
    assert 0 < mine[0]["E_av"] < 1e4 and mine[0]["eps_xH"] < 1.0, mine
    assert mine[0]["controller_params"] == \
        "kd_hip=250,kd_knee=50,kp_hip=100000,kp_knee=120000", mine
    assert [g["controller"] for g in segments] == ["pd_pf", "my_controller", "pd_pf"]
    assert "my_controller [" in text and "ran with its own parameters" in text


def test_controller_from_the_doc_joins_and_an_unsigned_one_is_counted(join_script, tmp_path):
    script = tmp_path / "spec_node.py"
    script.write_text(SPEC_NODE)
    s = join_script("--duration", "0", "--no-switch", "--no-builtin", "pd_p")
    key = key_file(s)
    s.wait_log("hexapod_sim", "lockstep mode")
    assert "pd_p_controller" not in json.loads((s.logs / "pids.json").read_text())
    spec = start_node(join_script, s, [sys.executable, str(script), "spec_ctl"], "spec_ctl",
                      HEXAPOD_KEY_FILE=key)
    rogue = start_node(join_script, s, [sys.executable, str(script), "unsigned_ctl"],
                       "unsigned_ctl", UNSIGNED="1", ANSWER_ALL="1", HEXAPOD_KEY_FILE="")

    run_segment(s, "spec_ctl")
    s.wait_log("hexapod_sim", f"dropped a message on {T.JOINT_COMMANDS}: unauthenticated "
               "(no valid 32-byte trailer")
    st = json.loads(hexapod_cli(s.domain, "status", "--json").stdout)["status"]
    dropped = int(st[f"dropped {T.JOINT_COMMANDS} (unauthenticated)"])
    assert dropped > 0 and "/unsigned_ctl" in st["outside_publishers"], st

    assert stop(s, spec, rogue) == 0, s.stderr()
    summary = [ln for ln in s.log("hexapod_sim").splitlines() if "stopped at tick" in ln]
    assert re.search(rf"{T.JOINT_COMMANDS} \d+ unauthenticated", summary[0]), summary
    # named as outside the graph: the unsigned node, not the joined one that signs
    outside = summary[0].split("publishers outside the graph:")[1]
    assert "/unsigned_ctl" in outside and "/spec_ctl" not in outside, summary
    _, segments = analyzed_segments(s)
    assert [g["controller"] for g in segments] == ["pd_pf", "spec_ctl", "pd_pf"], segments
    assert segments[1]["cycles"] >= 1 and "kp_hip=100000" in segments[1]["controller_params"]
    assert "unsigned_ctl" not in commands_by_frame(s.bag)  # dropped, never recorded


def test_joined_controller_death_holds_falls_back_and_exits_7(join_script, tmp_path):
    script = tmp_path / "spec_node.py"
    script.write_text(SPEC_NODE)
    # (1 s, not 5, to wait for the dead node's command: a slow takeover would show as a
    # missed tick before the kill, and the run must end in the fallback either way)
    s = join_script("--duration", "0", "--no-switch", "--no-builtin", "pd_p",
                    lockstep_timeout=1.0)
    key = key_file(s)
    s.wait_log("hexapod_sim", "lockstep mode")
    # Its own Fast DDS profile with the graph's 2 s lease (docs/controllers.md): with Fast
    # DDS's default 20 s lease the graph would see the killed node leave 20 s later.
    spec = start_node(join_script, s, [sys.executable, str(script), "spec_ctl"], "spec_ctl",
                      HEXAPOD_KEY_FILE=key,
                      FASTRTPS_DEFAULT_PROFILES_FILE=str(private_profile(
                          tmp_path, partition=partition_of(bytes.fromhex(
                              Path(key).read_text().strip())))))
    switch(s, "spec_ctl")
    switch_tick(s, "pd_pf", "spec_ctl")
    spec.kill()
    spec.wait(30)
    s.wait_log("hexapod_sim", "no command from spec_ctl since tick")
    s.wait_log("hexapod_sim", "spec_ctl silent for")
    s.wait_log("hexapod_sim", "falling back to joint damping")
    s.wait_log("hexapod_sim", "spec_ctl (node spec_ctl) has left the graph while in charge")
    code = stop(s)
    assert code == EXIT_CODES["fallback"], (code, s.stderr())
    assert "fallback episode(s)" in s.stderr(), s.stderr()


def test_joined_pd_law_in_charge_from_tick_0_equals_the_engines_pd_p(make_graph, tmp_path):
    """The example's law with PD-P's gains is PD-P (K_f = 1): a lockstep run with it in
    charge from tick 0 equals the in-process engine's PD-P run, tick for tick."""
    import numpy as np

    from hexapod_control.core.closed_loop import run
    from hexapod_metrics.bag import read_joint_state_arrays

    from .conftest import fast_params

    duration, bag = 2.0, tmp_path / "bag"
    g = make_graph(overrides=("sim.lockstep_timeout:=5",))  # a loaded machine: see join_script
    g.start("metrics", f"bag_path:={bag}")
    g.start("trajectory_generator")
    out = open(tmp_path / "my_controller.out", "wb")
    node = subprocess.Popen([str(EXAMPLE)], env=g.env, stdout=out, stderr=subprocess.STDOUT)
    try:
        g.start("hexapod_sim", "stop_at_end:=true", f"run.duration:={duration}",
                "run.controller:=my_controller",
                "wait_for:=trajectory_generator,my_controller,metrics")
        assert g.wait_exit("hexapod_sim", 300) == 0, g.log("hexapod_sim")
    finally:
        node.send_signal(signal.SIGINT)
        node.wait(30)
    g.stop_all(order=("trajectory_generator", "metrics"))
    assert "0 missed" in g.log("hexapod_sim")

    ref = run(fast_params(), "pd_p", duration)
    n = ref.obs.shape[0]
    with open_bag(bag) as b:
        obs = recorded_obs(b, n, 1_000_000)
        cmd = read_joint_state_arrays(b, T.JOINT_COMMANDS)
    assert np.array_equal(obs, ref.obs)
    assert np.array_equal(cmd.effort[:n - 1].reshape(-1, 6, 2), ref.command)


def test_with_authentication_off_an_unsigned_joined_controller_works(join_script, tmp_path,
                                                                      monkeypatch):
    monkeypatch.setenv("HEXAPOD_AUTH", "off")  # the graph's, the CLI's and the node's
    script = tmp_path / "spec_node.py"
    script.write_text(SPEC_NODE)
    s = join_script("--duration", "0", "--no-switch", "--no-builtin", "pd_p")
    s.wait_for(lambda: "HEXAPOD_AUTH=off (no key" in s.stdout(), 120, "the join line")
    s.wait_log("hexapod_sim", "lockstep mode")
    spec = start_node(join_script, s, [sys.executable, str(script), "spec_ctl"], "spec_ctl",
                      UNSIGNED="1")
    run_segment(s, "spec_ctl", cycles=1.2)
    st = json.loads(hexapod_cli(s.domain, "status", "--json").stdout)["status"]
    assert st["authentication"] == "off" and st["dropped"] == "0", st
    assert stop(s, spec) == 0, s.stderr()
    assert "authentication: off (HEXAPOD_AUTH=off)" in s.stdout() + s.stderr()  # the summary
    _, segments = analyzed_segments(s)
    assert [g["controller"] for g in segments] == ["pd_pf", "spec_ctl", "pd_pf"], segments


#: A managed (lifecycle) controller that joins unconfigured: it subscribes to the states
#: only once active and answers with zero torque (signed with the helper).
LIFECYCLE_NODE = r'''
import rclpy
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
from sensor_msgs.msg import JointState
from hexapod_common.auth import signer

JOINTS = [f"leg{i}_{j}" for i in range(1, 7) for j in ("hip", "knee")]


class Managed(LifecycleNode):
    def __init__(self):
        super().__init__("lc_ctl")
        self.sub = None

    def on_configure(self, state):
        self.sign = signer("/hexapod/joint_commands")
        self.pub = self.create_publisher(JointState, "/hexapod/joint_commands", 5000)
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state):
        self.sub = self.create_subscription(JointState, "/hexapod/joint_states", self.on_state,
                                            10)
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state):
        self.destroy_subscription(self.sub)
        return TransitionCallbackReturn.SUCCESS

    def on_state(self, m):
        if m.header.frame_id.split("/")[0] == "lc_ctl":
            z = [0.0] * 12
            cmd = JointState(name=JOINTS, position=z, velocity=z, effort=z)
            cmd.header.stamp, cmd.header.frame_id = m.header.stamp, "lc_ctl"
            self.pub.publish(self.sign.message(cmd))


rclpy.init()
node = Managed()
try:
    rclpy.spin(node)
except KeyboardInterrupt:
    pass
finally:
    node.destroy_node()
    rclpy.try_shutdown()
'''


def test_a_lifecycle_controller_that_joins_is_activated_by_switch(join_script, tmp_path):
    script = tmp_path / "lifecycle_node.py"
    script.write_text(LIFECYCLE_NODE)
    s = join_script("--duration", "0", "--no-switch")
    key = key_file(s)
    s.wait_log("hexapod_sim", "lockstep mode")
    node = start_node(join_script, s, [sys.executable, str(script)], "lc_ctl",
                      HEXAPOD_KEY_FILE=key)
    out = switch(s, "lc_ctl")
    assert "switching pd_pf -> lc_ctl at the next tick; lc_ctl was unconfigured, now active" \
        in out, out
    t0 = switch_tick(s, "pd_pf", "lc_ctl")
    s.wait_for(lambda: sim_time(s) > t0 + 0.02, 60, "ticks of lc_ctl")
    assert "switching lc_ctl -> pd_pf" in switch(s, "pd_pf")
    switch_tick(s, "lc_ctl", "pd_pf")
    # lc_ctl commands zero torque: if it stayed in charge for a whole cycle (a loaded
    # machine), the body sank and that cycle is not a walk (exit 8), rightly
    code = stop(s, node)
    assert code == 0 or (code == 8 and "fallen (exit 8)" in s.stderr()), s.stderr()
    frames = commands_by_frame(s.bag)
    assert frames.get("lc_ctl", 0) >= 20, frames
    assert sim_summary(s.log("hexapod_sim"))["switches"] == 2


def test_a_joined_controller_in_charge_from_tick_0_records_cleanly_and_analyses(join_script,
                                                                                  tmp_path):
    script = tmp_path / "spec_node.py"
    script.write_text(SPEC_NODE)
    s = join_script("--duration", "2.2", "--controller", "spec_ctl", "--no-switch")
    key = key_file(s)
    s.wait_log("hexapod_sim", "waiting for")
    spec = start_node(join_script, s, [sys.executable, str(script), "spec_ctl"], "spec_ctl",
                      HEXAPOD_KEY_FILE=key)
    code = s.wait(300)
    spec.send_signal(signal.SIGINT)
    spec.wait(30)
    assert code == 0, s.stderr()
    # the recorder takes the sim's announcement of the controller in charge at tick 0, made
    # before it may have discovered the joined node
    assert f"dropped a message on {T.ACTIVE_CONTROLLER}" not in s.log("metrics")
    with open_bag(s.bag) as b:
        announced = [(t, C.decode_string(bytes(d))) for _, t, d in
                     b.messages([T.ACTIVE_CONTROLLER])]
    assert announced == [(0, "spec_ctl")], announced
    _, segments = analyzed_segments(s)
    assert [g["controller"] for g in segments] == ["spec_ctl"], segments
    assert segments[0]["cycles"] >= 1 and "kp_hip=100000" in segments[0]["controller_params"]


def test_a_node_takes_a_builtins_place_under_the_builtins_node_name(join_script, tmp_path):
    """The naming rule (core/controller_names.py): a node named as a built-in controller
    (pd_p) serves none, and status and switch say how to take its place; a plain node named
    pd_p_controller serves pd_p where the launcher started none."""
    script = tmp_path / "spec_node.py"
    script.write_text(SPEC_NODE)
    s = join_script("--duration", "0", "--no-switch", "--no-builtin", "pd_p")
    key = key_file(s)
    s.wait_log("hexapod_sim", "lockstep mode")
    misnamed = start_node(join_script, s, [sys.executable, str(script), "pd_p"], "pd_p",
                          HEXAPOD_KEY_FILE=key)
    hint = ("node pd_p serves no controller: pd_p is a built-in controller's name, served by "
            "the node pd_p_controller")

    def status() -> str:
        r = hexapod_cli(s.domain, "status")
        assert r.returncode == 0, r.stderr
        return r.stdout
    s.wait_for(lambda: hint in status(), 60, "status naming the misnamed node")
    assert "controllers: pd_pf (node pd_pf_controller, active, in charge)\n" in status()
    r = hexapod_cli(s.domain, "switch", "pd_p")
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r
    assert "no controller node pd_p_controller on ROS_DOMAIN_ID=" in r.stderr, r.stderr
    assert hint in r.stderr, r.stderr
    misnamed.send_signal(signal.SIGINT)
    misnamed.wait(30)

    # a plain node in pd_p's place: switched to as any plain node (no lifecycle to ask)
    spec = start_node(join_script, s, [sys.executable, str(script), "pd_p_controller", "pd_p"],
                      "pd_p_controller", HEXAPOD_KEY_FILE=key)
    run_segment(s, "pd_p", cycles=1.2)
    assert stop(s, spec) == 0, s.stderr()
    frames = commands_by_frame(s.bag)
    assert frames.get("pd_p", 0) >= 1000, frames
    _, segments = analyzed_segments(s)
    assert [g["controller"] for g in segments] == ["pd_pf", "pd_p", "pd_pf"], segments
    # its own parameters, not the built-in's, read from the node at the switch
    assert "kp_hip=100000" in segments[1]["controller_params"], segments


def test_an_unsigned_controller_in_charge_is_named_outside_the_graph(join_script, tmp_path):
    """Switched to, an unsigned node's commands are dropped: it is not vouched for as a node
    of the graph (it was, by being in charge), so status and the summary name it."""
    script = tmp_path / "spec_node.py"
    script.write_text(SPEC_NODE)
    s = join_script("--duration", "0", "--no-switch", "--no-builtin", "pd_p",
                    lockstep_timeout=1.0)
    key_file(s)
    s.wait_log("hexapod_sim", "lockstep mode")
    rogue = start_node(join_script, s, [sys.executable, str(script), "unsigned_ctl"],
                       "unsigned_ctl", UNSIGNED="1", HEXAPOD_KEY_FILE="")
    switch(s, "unsigned_ctl")
    s.wait_log("hexapod_sim", f"dropped a message on {T.JOINT_COMMANDS}: unauthenticated")

    def named() -> bool:
        r = hexapod_cli(s.domain, "status")
        return f"publishers outside the graph: {T.JOINT_COMMANDS}: /unsigned_ctl" in r.stdout
    s.wait_for(named, 60, "status naming the unsigned controller")
    # its dropped commands leave the tick unanswered: after the 1 s cap, held then fallback
    s.wait_log("hexapod_sim", "falling back to joint damping")
    code = stop(s, rogue)
    assert code == EXIT_CODES["fallback"], (code, s.stderr())
    summary = [ln for ln in s.log("hexapod_sim").splitlines() if "stopped at tick" in ln]
    assert "/unsigned_ctl" in summary[0].split("publishers outside the graph:")[1], summary
