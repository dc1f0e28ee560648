"""The live view: a Foxglove WebSocket client gets the graph's joint states from the bridge,
and the graph's bag has every topic the repository's layout reads."""
from __future__ import annotations

import json
import re
import threading
from pathlib import Path


from hexapod_metrics.core.bag_params import read_records
from hexapod_metrics.bag import open_bag
from hexapod_metrics.bag.msgdefs import lookup
from hexapod_metrics.foxglove_layout import LAYOUT_FILE, layout_topics
from hexapod_common.core import topics as T

from .foxglove_ws import collect

ROOT = Path(__file__).resolve().parents[2]
NODES = "trajectory_generator,pd_pf_controller,metrics,markers,foxglove_bridge"
WANTED = 200  # joint states to receive over the WebSocket


def test_a_websocket_client_decodes_live_joint_states_and_the_bag_has_the_layouts_topics(
        make_graph, tmp_path):
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import JointState

    bag = tmp_path / "bag"
    g = make_graph()
    g.start("foxglove_bridge", "port:=0")
    g.wait_log("foxglove_bridge", "Foxglove WebSocket server on", 60)
    port = int(re.search(r"ws://127\.0\.0\.1:(\d+)", g.log("foxglove_bridge")).group(1))
    got: dict[str, object] = {}

    def client() -> None:
        try:
            got["result"] = collect(f"ws://127.0.0.1:{port}", T.JOINT_STATES, WANTED, 240)
        except Exception as err:  # noqa: BLE001 - reported by the test below
            got["error"] = err

    reader = threading.Thread(target=client)
    reader.start()
    g.start("metrics", f"bag_path:={bag}")
    g.start("trajectory_generator")
    g.start("pd_pf_controller")
    g.start("markers")
    g.start("hexapod_sim", "stop_at_end:=true", "run.duration:=2.0", f"wait_for:={NODES}")
    assert g.wait_exit("hexapod_sim", 300) == 0, g.log("hexapod_sim")
    reader.join(60)
    assert not reader.is_alive() and "error" not in got, got.get("error")
    g.stop_all(order=("trajectory_generator", "pd_pf_controller", "markers",
                      "foxglove_bridge", "metrics"))

    info, channel, frames = got["result"]
    assert "time" in info["capabilities"]
    assert channel["encoding"] == "cdr" and channel["schemaEncoding"] == "ros2msg"
    assert channel["schemaName"] == "sensor_msgs/msg/JointState"
    assert channel["schema"] == lookup("sensor_msgs/msg/JointState").definition
    assert len(frames) == WANTED
    stamps = []
    for log_time, payload in frames:
        msg = deserialize_message(payload, JointState)
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        assert stamp == log_time and stamp % 1_000_000 == 0
        assert tuple(msg.name) == T.JOINT_NAMES and msg.header.frame_id == "pd_pf"
        assert len(msg.position) == len(msg.velocity) == len(msg.effort) == 12
        stamps.append(stamp)
    assert stamps == sorted(set(stamps))
    # What the client got is byte for byte what the recorder stored at those ticks.
    with open_bag(bag) as b:
        recorded = {t: raw for _, t, raw in b.messages([T.JOINT_STATES])}
        topics = set(b.topics)
        counts = {name: info.message_count for name, info in b.topics.items()}
        starts = {r.node for r in read_records(b) if r.kind == "start"}
    # Every node that owns parameters left its start values in the bag.
    assert starts == {"hexapod_sim", "trajectory_generator", "pd_pf_controller", "metrics",
                      "markers", "foxglove_bridge"}
    for log_time, payload in frames:
        assert recorded[log_time] == payload
    read, _ = layout_topics(json.loads((ROOT / LAYOUT_FILE).read_text(encoding="utf-8")))
    assert read <= topics, read - topics
    assert all(counts[t] > 0 for t in read), {t: counts[t] for t in read}
