"""A lockstep graph run records exactly what the in-process closed loop computes."""
from __future__ import annotations

import re

import json
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from hexapod_control.core.closed_loop import run
from hexapod_metrics.bag import open_bag, read_joint_state_arrays
from hexapod_bringup.core.simulate import simulate
from hexapod_common.core import topics as T
from hexapod_common.core.params import load_params

from .bag_checks import bag_qos, recorded_obs
from .conftest import finish_recorded_run, start_recorded_run

DURATION = 3.0
PERIOD = 0.001  # 1 kHz at 1e-4 s physics (conftest.FAST_TIMING): three cycles, seconds of wall time


def test_lockstep_run_equals_the_in_process_loop_and_every_tick_is_recorded(make_graph,
                                                                             tmp_path):
    bag = tmp_path / "bag"
    g = make_graph()
    start_recorded_run(g, bag, DURATION)
    summary = finish_recorded_run(g, 300)
    assert summary["missed"] == 0 and summary["late"] == 0

    p = load_params(**{"sim.dt": 1e-4, "sim.control_period": PERIOD})
    ref = run(p, "pd_pf", DURATION)
    n = ref.obs.shape[0]  # ticks 0..N
    with open_bag(bag) as b:
        assert not b.truncated
        cols = {}
        for topic in T.STATE_TOPICS:
            a = read_joint_state_arrays(b, topic)
            stamps = np.arange(n) * 1_000_000
            assert np.array_equal(a.stamps, stamps), f"{topic}: a tick is missing"
            cols[topic] = (a.position, a.velocity, a.effort)
        obs = T.obs_from_columns(cols)
        np.testing.assert_allclose(obs, ref.obs, rtol=0, atol=1e-9)
        cmd = read_joint_state_arrays(b, T.JOINT_COMMANDS)
        assert np.array_equal(cmd.stamps[:n - 1], np.arange(n - 1) * 1_000_000)
        np.testing.assert_allclose(cmd.effort[:n - 1].reshape(-1, 6, 2), ref.command,
                                   rtol=0, atol=1e-9)

    # One topic table: the graph's bag carries the same QoS as `simulate --bag`'s.
    from hexapod_metrics.core.recording import write_run_bag

    sim_bag = write_run_bag(ref, tmp_path / "simulated")
    graph_qos, sim_qos = bag_qos(bag), bag_qos(sim_bag)
    assert {t: q for t, q in graph_qos.items() if t in sim_qos} == sim_qos
    assert graph_qos == {t: s.preset for t, s in T.TOPICS.items() if t in graph_qos}

    # The independent reader: every topic with the expected type and count.
    from rosbags.highlevel import AnyReader

    with AnyReader([Path(bag)]) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        msgs = [(c.topic, reader.deserialize(raw, c.msgtype)) for c, _, raw in reader.messages()]
    counts = Counter(t for t, _ in msgs)
    assert types[T.JOINT_STATES] == "sensor_msgs/msg/JointState"
    assert types[T.CLOCK] == "rosgraph_msgs/msg/Clock"
    assert types[T.ACTIVE_CONTROLLER] == "std_msgs/msg/String"
    assert types[T.INDICES] == types[T.STATUS] == "diagnostic_msgs/msg/DiagnosticArray"
    for topic in (T.JOINT_STATES, T.FOOT_FORCES, T.HIP_STATES, T.CLOCK):
        assert counts[topic] == n
    assert counts[T.JOINT_COMMANDS] >= n - 1 and counts[T.REFERENCE] >= n
    assert counts[T.INDICES] == 3
    assert [m.data for t, m in msgs if t == T.ACTIVE_CONTROLLER] == ["pd_pf"]

    # Online indices of the last cycle equal the in-process evaluation.
    last = [m for t, m in msgs if t == T.INDICES][-1].status[0]
    values = {kv.key: kv.value for kv in last.values}
    expected = simulate(p, "pd_pf", DURATION).indices
    assert values["controller"] == "pd_pf" and values["cycle"] == "2"
    for name in ("E_av", "T_L", "F_L", "eps_xH", "eps_yH", "eps_xF", "eps_yF", "lag_xH"):
        assert float(values[name]) == getattr(expected, name)
    # the hip lag's growth since cycle 1, beside eq. 11 (engine: cycle 1 = [1, 2] s)
    k1 = int(round(1.0 / PERIOD))
    sl = slice(k1, 2 * k1 + 1)
    from hexapod_metrics.core.indices import indices_from_obs

    cycle1 = indices_from_obs(ref.obs[sl], ref.reference.hip[sl], ref.reference.foot[sl], PERIOD)
    assert float(values["lag_growth"]) == pytest.approx(expected.lag_xH - cycle1.lag_xH,
                                                        rel=1e-9, abs=1e-15)
    report = json.loads((bag / "indices.json").read_text())
    assert report["segments"][0]["last_full_cycle"]["indices"]["eps_xH"] == expected.eps_xH

    # Offline analysis of the graph's bag gives the same numbers, per cycle and online.
    from hexapod_metrics.core.analysis import analyze_bag

    a = analyze_bag(bag)
    assert not a.truncated and [c.controller for c in a.cycles] == ["pd_pf"] * 3
    offline = a.cycles[-1].indices
    online = {c: idx for c, _, idx in a.online}
    for name in ("E_av", "T_L", "F_L", "eps_xH", "eps_yH", "eps_xF", "eps_yF"):
        assert getattr(offline, name) == pytest.approx(getattr(expected, name), rel=1e-12)
        assert getattr(online[2], name) == pytest.approx(getattr(offline, name), rel=1e-12)


def test_pd_pf_with_its_force_loop_in_the_drive_equals_the_engine_over_the_wire(make_graph,
                                                                                tmp_path):
    # pd_pf.force_loop = drive: the controller node sends 24-entry drive commands (setpoints
    # and gains), the sim's drive evaluates them at every physics step: the same numbers as
    # the engine's run_drive_ticks, bit for bit up to the wire's float64.
    bag = tmp_path / "bag"
    duration = 1.0
    g = make_graph(overrides=("pd_pf.force_loop:=drive",))
    start_recorded_run(g, bag, duration)
    summary = finish_recorded_run(g, 300)
    assert summary["missed"] == 0 and summary["late"] == 0
    assert "force loop in the drive" in g.log("pd_pf_controller")

    p = load_params(**{"sim.dt": 1e-4, "sim.control_period": PERIOD,
                       "pd_pf.force_loop": "drive"})
    ref = run(p, "pd_pf", duration)
    topic_loop = run(load_params(**{"sim.dt": 1e-4, "sim.control_period": PERIOD}), "pd_pf",
                     duration)
    n = ref.obs.shape[0]
    with open_bag(bag) as b:
        obs = recorded_obs(b, n, 1_000_000)
        np.testing.assert_allclose(obs, ref.obs, rtol=0, atol=1e-9)
        assert np.abs(obs - topic_loop.obs).max() > 1e-6  # another controller than topic's
        cmd = read_joint_state_arrays(b, T.JOINT_COMMANDS)
        assert cmd.names == T.DRIVE_COMMAND_NAMES
        drive = T.drive_command(cmd.position[0], cmd.velocity[0], cmd.effort[0])
        from hexapod_common.core.layout import C_KF, C_KP, C_TFF

        kf = p.pd_pf.kf
        assert np.all(drive[C_KF] == kf) and np.all(drive[C_TFF] == 0.0)
        assert np.all(drive[C_KP][:, 0] == kf * p.pd_pf.kp1)

    from rosbags.highlevel import AnyReader

    with AnyReader([Path(bag)]) as reader:  # an independent reader opens the 24-entry form
        conns = [c for c in reader.connections if c.topic == T.JOINT_COMMANDS]
        _, _, raw = next(reader.messages(connections=conns))
        msg = reader.deserialize(raw, conns[0].msgtype)
    assert list(msg.name) == list(T.DRIVE_COMMAND_NAMES) and len(msg.effort) == 24


@pytest.mark.parametrize("controller", ["pd_p", "pd_alpha"])
def test_every_registered_controller_on_the_graph_equals_the_engine(make_graph, tmp_path,
                                                                   controller):
    # pd_p in its built-in node; pd_alpha (a plain-Python plug-in,
    # hexapod_control.core.pd_alpha) in the generic controller node, named as the
    # controller, its law called per tick exactly as the engine's closed loop calls it. (pd_pf
    # and its drive mode: the tests above.) In charge from tick 0, the lockstep run equals
    # `run(p, controller)` bit for bit. The pd_p run is paced (sim.lockstep_max_rtf = 0.5: a
    # tick goes out no sooner than 2 periods of wall time after the last): same numbers,
    # at most half real time.
    from hexapod_common.core.controller_names import node_of

    bag = tmp_path / "bag"
    duration = 0.5
    max_rtf = 0.5 if controller == "pd_p" else 0.0
    node = node_of(controller)
    g = make_graph()
    g.start("metrics", f"bag_path:={bag}")
    g.start("trajectory_generator")
    g.start(node)
    g.start("hexapod_sim", "stop_at_end:=true", f"run.duration:={duration}",
            f"run.controller:={controller}", f"wait_for:=trajectory_generator,{node},metrics",
            f"sim.lockstep_max_rtf:={max_rtf}")
    summary = finish_recorded_run(g, 300)
    assert summary["missed"] == 0 and summary["late"] == 0
    if max_rtf:
        rtf = float(re.search(r"real-time factor ([\d.]+)", g.log("hexapod_sim")).group(1))
        assert 0 < rtf <= max_rtf * 1.005, rtf  # (k - 1) paced gaps over k ticks
    if controller == "pd_alpha":
        assert "configured: PdAlphaParams(" in g.log(node)

    p = load_params(**{"sim.dt": 1e-4, "sim.control_period": PERIOD})
    ref = run(p, controller, duration)
    n = ref.obs.shape[0]
    with open_bag(bag) as b:
        np.testing.assert_array_equal(recorded_obs(b, n, 1_000_000), ref.obs)
        cmd = read_joint_state_arrays(b, T.JOINT_COMMANDS)
        assert cmd.names == T.JOINT_NAMES  # torque-only: the 12-entry form
        np.testing.assert_array_equal(cmd.effort[:n - 1].reshape(-1, 6, 2), ref.command)


def test_a_monte_carlo_seed_replays_bit_for_bit_in_the_graph(make_graph, tmp_path):
    # The sim node's ground_seed / ground_spread draw the factors `hexapod montecarlo
    # --first-seed K` uses: the lockstep graph run equals the engine's run of that seed.
    from hexapod_bringup.core.montecarlo import simulate_on_ground
    from hexapod_metrics.bag import read_joint_state_topics

    bag = tmp_path / "bag"
    duration, seed, spread = 1.0, 7, 0.3
    g = make_graph()
    g.start("metrics", f"bag_path:={bag}")
    g.start("trajectory_generator")
    g.start("pd_pf_controller")
    g.start("hexapod_sim", "stop_at_end:=true", f"run.duration:={duration}",
            f"ground_seed:={seed}", f"ground_spread:={spread}", "summary_path:="
            f"{tmp_path / 'summary.json'}",
            "wait_for:=trajectory_generator,pd_pf_controller,metrics")
    summary = finish_recorded_run(g, 300)
    assert summary["missed"] == 0
    p = load_params(**{"sim.dt": 1e-4, "sim.control_period": PERIOD})
    ref = simulate_on_ground(p, "pd_pf", seed, spread, duration)
    n = ref.run.obs.shape[0]
    with open_bag(bag) as b:
        cols = read_joint_state_topics(b, list(T.STATE_TOPICS))
        obs = T.obs_from_columns({t: (a.position, a.velocity, a.effort)
                                  for t, a in cols.items()})
    assert obs.shape[0] == n
    np.testing.assert_array_equal(obs, ref.run.obs)
    uniform = run(p, "pd_pf", duration)
    assert np.abs(obs - uniform.obs).max() > 1e-6  # the ground was uneven
    used = json.loads((tmp_path / "summary.json").read_text())["ground"]
    assert used["seed"] == seed and used["touchdowns"] == list(ref.run.ground.touchdowns)
    assert not used["overflowed"]
