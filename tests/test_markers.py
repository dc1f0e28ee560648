"""Foxglove markers: the stick figure as a MarkerArray that bag readers decode."""
from pathlib import Path

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy", reason="the marker node needs rclpy (scripts/setup.sh)")


def test_markers_of_a_run_round_trip_through_a_bag(tmp_path):
    from rclpy.serialization import serialize_message
    from rosbags.highlevel import AnyReader

    from hexapod_control.core.closed_loop import run
    from hexapod_metrics.bag import BagWriter
    from hexapod_metrics.core.figure import stick_figure
    from hexapod_metrics.marker_node import markers
    from hexapod_common.core.params import load_params

    FAST = {"sim.dt": 1e-4, "sim.control_period": 1e-3}  # 1 kHz: a small run

    r = run(load_params(**FAST), "pd_pf", 1.0)
    k = 700  # legs 2, 3, 6 in stance
    msg = markers(r.obs[k], 1.0, k * 1_000_000)
    fig = stick_figure(r.obs[k], 1.0)
    legs = msg.markers[0]
    assert len(legs.points) == 24
    # leg 1: hip, knee, knee, foot
    assert (legs.points[3].x, legs.points[3].z) == pytest.approx(tuple(fig.foot[0]))
    assert len(msg.markers[2].points) == int(fig.contact.sum()) >= 3
    with BagWriter(tmp_path / "m") as bag:
        bag.add_topic("/hexapod/markers", "visualization_msgs/msg/MarkerArray")
        bag.write("/hexapod/markers", k * 1_000_000, serialize_message(msg))
    with AnyReader([Path(tmp_path / "m")]) as reader:
        (con, ts, raw), = list(reader.messages())
        back = reader.deserialize(raw, con.msgtype)
    assert len(back.markers) == len(msg.markers)
    assert np.isclose(back.markers[0].points[3].z, legs.points[3].z)
