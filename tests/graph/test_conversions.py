"""Messages <-> arrays (hexapod_common.runtime.conversions) and the ROS side of parameters."""
from __future__ import annotations

import math

import numpy as np
import pytest

from hexapod_common.runtime import conversions as C
from hexapod_common.core import topics as T
from hexapod_common.core.params import SPECS


@pytest.mark.parametrize("topic", sorted(C.CODECS))
@pytest.mark.parametrize("frame", ["", "x", "pd_p", "pd_pf", "abcdefgh"])
def test_joint_state_codec_matches_rclpy(topic, frame):
    from rclpy.serialization import deserialize_message, serialize_message
    from sensor_msgs.msg import JointState

    codec = C.CODECS[topic]
    rng = np.random.default_rng(len(frame))
    pos, vel, eff = rng.standard_normal((3, codec.n))
    stamp = 12_345_678_901_234
    ours = codec.encode(stamp, frame, pos, vel, eff)
    theirs = serialize_message(C.joint_state(T.Columns(codec.names, pos, vel, eff), stamp,
                                             frame))
    assert len(ours) == len(theirs)
    msg = deserialize_message(ours, JointState)
    assert C.from_time(msg.header.stamp) == stamp and msg.header.frame_id == frame
    assert tuple(msg.name) == codec.names and list(msg.effort) == list(eff)
    for data in (ours, theirs):  # rclpy leaves padding bytes uninitialised: generic path
        view = codec.decode(data)
        assert (view.stamp_ns, view.frame_id) == (stamp, frame)
        assert np.array_equal(view.position, pos) and np.array_equal(view.velocity, vel)
        assert np.array_equal(view.effort, eff)


def test_codec_rejects_a_message_of_another_topic():
    data = C.CODECS[T.JOINT_STATES].encode(0, "", np.zeros(12), np.zeros(12), np.zeros(12))
    with pytest.raises(ValueError, match="leg1_foot_x..leg6_foot_y"):
        C.CODECS[T.FOOT_FORCES].decode(data)


def test_small_messages_match_rclpy():
    from rclpy.serialization import serialize_message

    assert C.encode_clock(1_500_000_001) == serialize_message(C.clock(1_500_000_001))
    assert C.encode_string("pd_pf") == serialize_message(C.string("pd_pf"))
    assert C.decode_string(C.encode_string("pd_pf") + b"\0\0") == "pd_pf"
    assert C.decode_stamp(C.encode_clock(3_000_000_007)) == 3_000_000_007
    assert C.tick_of(T.stamp_ns(1234 * 0.001), 1_000_000) == 1234


def test_diagnostics_round_trip():
    msg = C.diagnostic_array(5, [C.Status("hexapod_sim", "error", "fallback", {"tick": "7"})])
    (st,) = C.statuses(msg)
    assert (st.level, st.message, dict(st.values)) == ("error", "fallback", {"tick": "7"})
    assert C.from_time(msg.header.stamp) == 5


@pytest.mark.parametrize("statuses", [
    [],
    [C.Status("hexapod_sim", "error", "fallback", {"tick": "7"})],
    [C.Status("a", "ok", "", {}), C.Status("metrics", "warn", "dropped 3 ünïcode",
                                           {"k1": "v", "k22": "", "": "x" * 33}, "hw")],
])
def test_raw_diagnostic_arrays_are_rclpys_bytes(statuses):
    from rclpy.serialization import serialize_message

    from hexapod_common.core.cdr import cdr_padding_mask

    ours = C.encode_statuses(1_234_567_891, statuses)
    theirs = serialize_message(C.diagnostic_array(1_234_567_891, statuses))
    assert len(ours) == len(theirs)
    # rclpy leaves padding bytes uninitialised: equal everywhere else
    mask = cdr_padding_mask(theirs, T.DIAGNOSTIC_ARRAY)
    assert mask == cdr_padding_mask(ours, T.DIAGNOSTIC_ARRAY)
    assert all(a == b for a, b, m in zip(ours, theirs, mask) if not m)
    assert all(b == 0 for b, m in zip(ours, mask) if m)


def test_fill_obs_is_the_inverse_of_state_columns():
    obs = np.random.default_rng(1).standard_normal((9, 6, 2))
    out = np.zeros_like(obs)
    for topic in T.STATE_TOPICS:
        c = T.state_columns(obs, topic)
        C.fill_obs(out, topic, c.position, c.velocity, c.effort)
    assert np.array_equal(out, obs)


def test_descriptors_come_from_the_specs():
    from hexapod_common.runtime.ros_params import descriptor, is_live

    assert descriptor("robot.leg_length_1", SPECS["robot.leg_length_1"]).read_only
    assert descriptor("sim.dt", SPECS["sim.dt"]).read_only
    assert descriptor("gait.velocity", SPECS["gait.velocity"]).read_only
    for name in ("ground.k_y", "actuator.t_max", "pd_p.kp1", "pd_pf.kf", "run.controller",
                 "sim.lockstep_timeout", "sim.lockstep_max_rtf", "sim.hold_time",
                 "sim.fallback_damping"):
        assert is_live(name) and not descriptor(name, SPECS[name]).read_only
    d = descriptor("ground.k_y", SPECS["ground.k_y"])
    assert d.floating_point_range[0].from_value == 0.0
    assert d.floating_point_range[0].to_value == 1e12
    assert not descriptor("actuator.t_max", SPECS["actuator.t_max"]).floating_point_range
    assert "N m" in descriptor("actuator.t_max", SPECS["actuator.t_max"]).description
    assert descriptor("run.eval_cycles", SPECS["run.eval_cycles"]).integer_range[0].to_value \
        == 1000


def test_inf_in_a_params_file_reaches_the_node(tmp_path):
    """rcl's params-file parser reads `.inf` as float infinity (ideal actuators)."""
    import rclpy
    from rclpy.context import Context

    from hexapod_common.runtime.ros_params import declare_params

    path = tmp_path / "p.yaml"
    path.write_text("/**:\n  ros__parameters:\n    actuator:\n      t_max: .inf\n")
    ctx = Context()
    rclpy.init(context=ctx, args=["--ros-args", "--params-file", str(path)], domain_id=101)
    try:
        node = rclpy.create_node("inf_probe", context=ctx)
        assert math.isinf(declare_params(node).actuator.t_max)
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)
