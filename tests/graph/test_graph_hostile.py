"""Hostile processes on the graph's domain: a fuzzer and a rogue (real node processes).

* Fuzz: random, empty, truncated and wrong-shape messages, NaN values and stamps outside the
  run on every topic the graph subscribes to, half of them with a valid tag (as if a
  buggy node of the graph sent them). Every node survives; the drops are counted per topic
  and cause and reported; the lockstep run is bit for bit the clean run.
* Rogue: a node that answers the states with its own commands (stamp and frame_id copied),
  forges states, references and the controller in charge, and replays or tampers with the
  graph's signed messages. Nothing of it is applied or recorded; it is reported by name.

The clean run is the in-process closed loop, which a clean lockstep graph run equals bit
for bit (test_graph_lockstep.py); realtime runs are checked tick by tick instead: every
recorded command is what the control law gives for the recorded inputs, and every applied
torque is one of those commands (or the torque held).
"""
from __future__ import annotations

import json
import re
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hexapod_control.core.closed_loop import run
from hexapod_control.core.controllers import control_law, controller_code, gain_vector
from hexapod_metrics.bag import open_bag, read_joint_state_arrays
from hexapod_metrics.core.bag_params import bag_params
from hexapod_common.runtime import conversions as C
from hexapod_common.core import msg_checks as M
from hexapod_common.core import topics as T

from .conftest import fast_params, sim_summary

HOSTILE = Path(__file__).with_name("hostile_node.py")
CONTROLLED = (T.JOINT_STATES, T.FOOT_FORCES, T.HIP_STATES, T.REFERENCE, T.JOINT_COMMANDS)


def _start_hostile(g, kind: str, tmp_path: Path, sign: bool, outsider: bool = False
                   ) -> tuple[subprocess.Popen, Path]:
    """The hostile node: with the graph's environment (its DDS profile, hence the run's
    partition, as if it had read the partition's name off the discovery traffic; the key
    only to ``sign``), or as an ``outsider`` without either (acting blind)."""
    out = tmp_path / f"{kind}.json"
    log = open(tmp_path / f"{kind}.log", "wb")
    args = [sys.executable, str(HOSTILE), kind, "--out", str(out), "--name", f"{kind}_node"]
    env = g.env
    if outsider:
        env = {k: v for k, v in env.items()
               if k not in ("FASTRTPS_DEFAULT_PROFILES_FILE", "HEXAPOD_KEY_FILE")}
        args.append("--blind")
    proc = subprocess.Popen(args + (["--sign"] if sign else []), env=env, stdout=log,
                            stderr=subprocess.STDOUT, start_new_session=True)
    return proc, out


def _run(make_graph, tmp_path: Path, kind: str, mode: str, period: float, duration: float,
         sign: bool = False, outsider: bool = False):
    bag = tmp_path / "bag"
    # A long lockstep timeout: on this shared 2-core machine a starved process can take
    # more than the default 0.5 s to answer, which would be a missed tick, not the hostile
    # node's doing (the lockstep run must then equal the clean run exactly).
    g = make_graph(overrides=(f"sim.control_period:={period}", f"sim.mode:={mode}",
                              "sim.lockstep_timeout:=20.0"))
    g.start("metrics", f"bag_path:={bag}")
    for node in ("trajectory_generator", "pd_p_controller", "pd_pf_controller"):
        g.start(node)
    hostile, out = _start_hostile(g, kind, tmp_path, sign, outsider)
    try:
        # The sim starts once the hostile node is matched too: it acts from tick 0.
        g.start("hexapod_sim", "stop_at_end:=true", f"run.duration:={duration}",
                "wait_for:=trajectory_generator,pd_p_controller,pd_pf_controller,metrics,"
                f"{kind}_node")
        code = g.wait_exit("hexapod_sim", 400)
    finally:
        hostile.send_signal(signal.SIGTERM)
        hostile_code = hostile.wait(30)
    assert code == 0, g.log("hexapod_sim")
    assert hostile_code == 0 and "hostile: active" in (tmp_path / f"{kind}.log").read_text()
    codes = g.stop_all(order=("trajectory_generator", "pd_p_controller", "pd_pf_controller",
                              "metrics"))
    logs = {n: g.log(n) for n in ("hexapod_sim", "trajectory_generator", "pd_p_controller",
                                  "pd_pf_controller", "metrics")}
    assert all(c == 0 for c in codes.values()), codes  # no node died of what it received
    for name, log in logs.items():
        assert "Traceback" not in log, f"{name}:\n{log[-3000:]}"
    sent = json.loads(out.read_text())["sent"]
    report = json.loads((bag / "indices.json").read_text())
    return bag, logs, sent, report


def _read(bag: Path) -> dict:
    with open_bag(bag) as b:
        assert not b.truncated
        arrays = {t: read_joint_state_arrays(b, t) for t in CONTROLLED}
        announced = [C.decode_string(bytes(d)) for _, _, d in b.messages([T.ACTIVE_CONTROLLER])]
        clock = [C.decode_stamp(bytes(d)) for _, _, d in b.messages([T.CLOCK])]
        statuses = [bytes(d) for _, _, d in b.messages([T.STATUS])]
        params = bag_params(b)
    return {"arrays": arrays, "announced": announced, "clock": clock, "status": statuses,
            "params": params}


def _assert_equals_clean_run(rec: dict, duration: float) -> None:
    """Bit for bit the in-process run: every state, reference and command of every tick."""
    ref = run(fast_params(), "pd_pf", duration)
    n = ref.obs.shape[0]
    a = rec["arrays"]
    ticks = np.arange(n) * 1_000_000
    for topic in (T.JOINT_STATES, T.FOOT_FORCES, T.HIP_STATES, T.REFERENCE):
        assert np.array_equal(a[topic].stamps[:n], ticks), topic
    assert rec["clock"][:n] == list(ticks)
    obs = T.obs_from_columns({t: (a[t].position[:n], a[t].velocity[:n], a[t].effort[:n])
                              for t in T.STATE_TOPICS})
    assert np.array_equal(obs, ref.obs)
    r = ref.reference
    expected = T.reference_columns
    want = np.array([expected(r.theta[k], r.theta_vel[k], r.hip[k], r.hip_vel[k], r.foot[k],
                              r.foot_vel[k]).position for k in range(n)])
    assert np.array_equal(a[T.REFERENCE].position[:n], want)
    cmd = a[T.JOINT_COMMANDS]
    # One command per tick, no other (the last state, tick n - 1, may be answered too).
    assert len(cmd.stamps) in (n - 1, n) and np.array_equal(cmd.stamps, ticks[:len(cmd.stamps)])
    assert np.array_equal(cmd.effort[:n - 1].reshape(-1, 6, 2), ref.command)
    assert rec["announced"] == ["pd_pf"]


def _assert_genuine_realtime(rec: dict, period: float) -> None:
    """Every recorded command is the control law of the recorded inputs, every applied
    torque one of those commands (saturated) or the one held, every tick recorded."""
    p = fast_params()
    a = rec["arrays"]
    period_ns = int(round(period * 1e9))
    js = a[T.JOINT_STATES]
    n = len(js.stamps)
    assert n > 100 and np.array_equal(js.stamps, np.arange(n) * period_ns)
    assert rec["announced"] == ["pd_pf"]
    index = {t: {int(s): i for i, s in enumerate(a[t].stamps)} for t in CONTROLLED}
    gains = gain_vector(p.gains("pd_pf"))
    code = controller_code("pd_pf")
    cmd = a[T.JOINT_COMMANDS]
    assert len(cmd.stamps) > n // 2
    demand = np.empty((6, 2))
    applied = [np.zeros((6, 2))]
    for j, s in enumerate(cmd.stamps):
        k = {t: index[t][int(s)] for t in (T.JOINT_STATES, T.FOOT_FORCES, T.HIP_STATES)}
        obs = T.obs_from_columns({t: (a[t].position[k[t]], a[t].velocity[k[t]],
                                      a[t].effort[k[t]]) for t in T.STATE_TOPICS})
        r = T.split_reference(a[T.REFERENCE].position[index[T.REFERENCE][int(s)]],
                              a[T.REFERENCE].velocity[index[T.REFERENCE][int(s)]])
        control_law(code, gains, obs, r["theta"], r["theta_vel"], p.robot.leg_length_1,
                    p.robot.leg_length_2, demand)
        assert np.array_equal(demand.ravel(), cmd.effort[j]), f"command of tick {s}"
        applied.append(np.clip(demand, -p.actuator.t_max, p.actuator.t_max))
    allowed = {x.tobytes() for x in applied}
    effort = js.effort.reshape(-1, 6, 2)
    velocity = js.velocity.reshape(-1, 6, 2)
    t_max, damping = p.actuator.t_max, p.sim.fallback_damping
    for k in range(1, n):
        fallback = np.clip(-damping * velocity[k - 1], -t_max, t_max)  # the sim's own
        assert (effort[k].tobytes() in allowed or np.array_equal(effort[k], effort[k - 1])
                or np.array_equal(effort[k], fallback)), (
            f"tick {k}: applied torque {effort[k].ravel()} is no command of the controller")


def _assert_run_unchanged(rec: dict, logs: dict[str, str], mode: str, period: float,
                          duration: float) -> None:
    """Lockstep: the bag equals a clean run and no tick was missed or late; realtime: every
    command the sim took was the genuine controller's."""
    if mode == "lockstep":
        _assert_equals_clean_run(rec, duration)
        summary = sim_summary(logs["hexapod_sim"])
        assert summary["missed"] == 0 and summary["late"] == 0
    else:
        _assert_genuine_realtime(rec, period)


def _status_values(rec: dict, node: str) -> dict[str, str]:
    from hexapod_common.core import cdr

    last = {}
    for data in rec["status"]:
        for st in cdr.decode_diagnostic_array(data)[1]:
            if st.name == node:
                last = dict(st.values)
    assert last, f"no status of {node} in the bag"
    return last


@pytest.mark.parametrize("mode, period, duration", [
    ("lockstep", 0.001, 3.0),
    pytest.param("realtime", 0.004, 4.0, marks=pytest.mark.realtime),  # 250 Hz: see
    # test_graph_switch.py for the rate
])
def test_fuzz_on_every_subscribed_topic_is_dropped_counted_and_changes_nothing(
        make_graph, tmp_path, mode, period, duration):
    bag, logs, sent, report = _run(make_graph, tmp_path, "fuzz", mode, period, duration,
                                   sign=True)
    # The fuzzer reached every topic, signed and not, with every kind of bad message.
    topics = {k.split(" ")[0] for k in sent}
    assert topics >= {T.JOINT_STATES, T.FOOT_FORCES, T.HIP_STATES, T.REFERENCE,
                      T.JOINT_COMMANDS, T.ACTIVE_CONTROLLER, T.STATUS, T.MARKERS,
                      T.RECORDED}
    assert sum(n for k, n in sent.items() if k.endswith("(signed)")) > 50
    for kind in ("random", "empty", "truncated", "wrong names", "short array", "NaN",
                 "stamp 1e6 s", "negative stamp", "unknown controller", "negative drive gain"):
        assert any(kind in k for k in sent), kind

    rec = _read(bag)
    _assert_run_unchanged(rec, logs, mode, period, duration)

    # Counted per topic and cause, reported in the summary, the status and the log.
    dropped = report["dropped"]
    for topic, cause in ((T.JOINT_STATES, M.UNAUTHENTICATED), (T.JOINT_STATES, M.NON_FINITE),
                         (T.JOINT_STATES, M.BAD_STAMP), (T.JOINT_STATES, M.WRONG_SHAPE),
                         (T.JOINT_STATES, M.UNDECODABLE), (T.REFERENCE, M.NON_FINITE),
                         (T.JOINT_COMMANDS, M.WRONG_SHAPE),
                         (T.JOINT_COMMANDS, M.NEGATIVE_GAIN),
                         (T.ACTIVE_CONTROLLER, M.BAD_CONTENT), (T.STATUS, M.UNDECODABLE),
                         (T.MARKERS, M.UNAUTHENTICATED)):
        assert dropped.get(f"{topic} ({cause})", 0) > 0, (topic, cause, dropped)
    sim_line = [line for line in logs["hexapod_sim"].splitlines() if "stopped at tick" in line]
    assert f"{T.JOINT_COMMANDS} " in sim_line[0].split("inputs: dropped")[1]
    if mode == "lockstep":  # the recorder's progress: the sim reads it in lockstep only
        for cause in ("unauthenticated", "undecodable"):
            assert re.search(rf"{T.RECORDED} \d+ {cause}", sim_line[0]), (cause, sim_line)
    values = _status_values(rec, "hexapod_sim")
    assert int(values["dropped"]) > 0 and values["authentication"] == "on"
    assert any(k.startswith(f"dropped {T.JOINT_COMMANDS} (") for k in values)
    assert f"dropped a message on {T.JOINT_STATES}" in logs["pd_pf_controller"]
    assert "inputs: dropped" in logs["pd_p_controller"]
    # the controllers' wake-up topic: garbage and forgeries dropped and counted, not obeyed
    for node in ("pd_p_controller", "pd_pf_controller"):
        assert f"dropped a message on {T.ACTIVE_CONTROLLER}" in logs[node], node
    assert f"dropped a message on {T.JOINT_STATES}" in logs["trajectory_generator"]


@pytest.mark.parametrize("mode, period, duration", [
    ("lockstep", 0.001, 3.0),
    pytest.param("realtime", 0.004, 4.0, marks=pytest.mark.realtime),
])
def test_rogue_node_is_not_at_the_controls_and_is_reported(make_graph, tmp_path, mode, period,
                                                           duration):
    bag, logs, sent, report = _run(make_graph, tmp_path, "rogue", mode, period, duration)
    for what in (f"{T.JOINT_COMMANDS} stamp-copying command",
                 f"{T.JOINT_COMMANDS} constant stale command", f"{T.JOINT_COMMANDS} replayed",
                 f"{T.JOINT_COMMANDS} tampered", f"{T.JOINT_STATES} forged +0.1 rad",
                 f"{T.JOINT_STATES} replayed at once", f"{T.JOINT_STATES} replayed 50 ticks later",
                 f"{T.REFERENCE} forged +0.2 rad", f"{T.ACTIVE_CONTROLLER} forged controller",
                 f"{T.PARAMETERS} forged ground change"):
        assert sent.get(what, 0) > 0, (what, sent)

    rec = _read(bag)
    _assert_run_unchanged(rec, logs, mode, period, duration)

    # Reported: who, which topic, how many.
    who = "/rogue_node"
    assert (f"publishers on {T.JOINT_COMMANDS} that are not nodes of this graph: {who}"
            in logs["hexapod_sim"])
    sim_line = [line for line in logs["hexapod_sim"].splitlines() if "stopped at tick" in line]
    assert f"publishers outside the graph: {T.JOINT_COMMANDS}: {who}" in sim_line[0]
    values = _status_values(rec, "hexapod_sim")
    assert who in values["outside_publishers"]
    assert int(values[f"dropped {T.JOINT_COMMANDS} ({M.UNAUTHENTICATED})"]) > 0
    assert int(values[f"dropped {T.JOINT_COMMANDS} ({M.REPLAYED})"]) > 0
    for topic in (T.JOINT_STATES, T.REFERENCE, T.ACTIVE_CONTROLLER, T.JOINT_COMMANDS):
        assert who in report["outside_publishers"][topic], topic
    assert report["dropped"][f"{T.JOINT_STATES} ({M.REPLAYED})"] > 0
    assert report["dropped"][f"{T.ACTIVE_CONTROLLER} ({M.UNAUTHENTICATED})"] > 0
    # A forged parameter record (valid checksum, the sim's name) changes nothing recorded.
    assert report["dropped"][f"{T.PARAMETERS} ({M.UNAUTHENTICATED})"] > 0
    assert rec["params"].timeline.changes == () and rec["params"].params.ground.scale == 1.0
    assert all(r.node != "hexapod_sim" or r.kind == "start" for r in rec["params"].records)
    for node in ("pd_pf_controller", "trajectory_generator"):
        assert (f"publishers on {T.JOINT_STATES} that are not nodes of this graph: {who}"
                in logs[node])


def test_an_outsiders_flood_of_the_tick_topics_wakes_no_node(make_graph, tmp_path):
    """The tick topics live in the run's DDS partition (dds_profile.PARTITIONED_TOPICS): a
    fuzzer on the domain without the run's profile reaches none of the graph's readers of
    them (nothing to drop, nothing decoded: no wake-up), only the default partition's
    topics, where it is dropped, counted and named; the run is unchanged."""
    from hexapod_common.runtime.dds_profile import PARTITIONED_TOPICS

    duration = 3.0
    bag, logs, sent, report = _run(make_graph, tmp_path, "fuzz", "lockstep", 0.001, duration,
                                   outsider=True)
    for topic in CONTROLLED:
        assert sum(n for k, n in sent.items() if k.startswith(topic + " ")) > 20, topic
    dropped = report["dropped"]
    assert not [k for k in dropped if k.split(" ")[0] in PARTITIONED_TOPICS], dropped
    for topic in (T.ACTIVE_CONTROLLER, T.STATUS, T.PARAMETERS):  # reached, and refused
        assert dropped.get(f"{topic} ({M.UNAUTHENTICATED})", 0) > 20, dropped
    _assert_run_unchanged(_read(bag), logs, "lockstep", 0.001, duration)
    # named where its messages arrive (on the tick topics nothing of it does: rclpy cannot
    # tell a publisher outside the partition from a controller that joined the graph)
    assert "/fuzz_node" in report["outside_publishers"][T.STATUS]
