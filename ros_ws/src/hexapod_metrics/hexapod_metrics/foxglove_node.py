"""Node ``foxglove_bridge``: the graph's topics live over the Foxglove WebSocket protocol.

Every topic a bag records (:data:`~hexapod_metrics.core.recording.TOPICS`) is subscribed raw
and forwarded as it is: CDR bytes on a channel with the topic's full ``ros2msg`` schema
(the same definitions the bags carry), through the ``foxglove-sdk`` WebSocket server on
``host:port`` (parameters; default ``127.0.0.1:8765``, localhost only). A message is logged
at its own stamp (simulated time; the markers at their first marker's stamp, the active
controller at the latest ``/clock``), and the server broadcasts the simulated time so that
Foxglove's clock follows the sim. Open Foxglove, "Open connection", Foxglove WebSocket,
``ws://localhost:8765``, and load ``docs/foxglove/hexapod_layout.json``.

The node only reads: messages are taken in batches (``batch_interval``) at low priority
(``scripts/run_graph.sh`` starts it niced), like the recorder.
"""
from __future__ import annotations

import struct
import sys
from typing import Any

from hexapod_common.core import topics as T
from hexapod_common.core.errors import HexapodError
from hexapod_common.core.topics import TOPICS
from hexapod_common.runtime.hot_loop import FastLogger, HotLoop
from hexapod_common.runtime.input_guard import SIGNED_TOPICS, InputGuard
from hexapod_common.runtime.node_main import run_node
from hexapod_common.runtime.param_topic import ParamAnnouncer
from hexapod_common.runtime.ros_params import declare_node_param
from hexapod_common.runtime.rt_sched import use_rt_priority
from rclpy.node import Node

from hexapod_common.runtime import conversions as C

from .bag.msgdefs import lookup

_STAMP = struct.Struct("<iI")
#: Topics whose messages start with a std_msgs/Header (or are a Clock): stamp at byte 4.
STAMPED = {t for t, spec in TOPICS.items()
           if spec.msg_type not in ("std_msgs/msg/String", "visualization_msgs/msg/MarkerArray")}


def marker_stamp(data: bytes) -> int | None:
    """Stamp (ns) of the first marker of a serialized MarkerArray, None if it has none."""
    if len(data) < 16 or int.from_bytes(data[4:8], "little") == 0:
        return None
    sec, nsec = _STAMP.unpack_from(data, 8)
    return sec * 1_000_000_000 + nsec


class FoxgloveBridge(Node):
    """Forwards the recorded topics to Foxglove clients."""

    def __init__(self) -> None:
        super().__init__("foxglove_bridge")
        import foxglove

        self.log = FastLogger(self.get_logger().name)
        host = declare_node_param(self, "host")
        port = declare_node_param(self, "port")
        batch = declare_node_param(self, "batch_interval")
        # Its Fast DDS threads under SCHED_FIFO when asked (runtime/rt_sched.py).
        self.rt = use_rt_priority(self, self.log, main=False)
        try:
            self.server = foxglove.start_server(
                name="hexapod", host=host, port=port,
                capabilities=[foxglove.Capability.Time])
        except Exception as err:  # noqa: BLE001 - the SDK raises its own runtime errors
            raise HexapodError(f"cannot serve Foxglove on {host}:{port}: {err}") from err
        self.port = self.server.port
        self.clock_ns = 0
        self.sent = 0
        self.channels: dict[str, Any] = {}
        self.guard = InputGuard(self, self.log)  # forwards only the graph's own messages
        self.loop = HotLoop(self, batch_interval=batch)
        for topic, spec in TOPICS.items():
            msgtype = spec.msg_type
            definition = lookup(msgtype)
            assert definition is not None, msgtype
            schema = foxglove.Schema(name=msgtype, encoding="ros2msg",
                                     data=definition.definition.encode())
            self.channels[topic] = foxglove.Channel(topic, message_encoding="cdr",
                                                    schema=schema)
            q = C.TOPIC_QOS[topic]
            # commands volatile: a joined controller publishing with rclpy's defaults
            self.loop.subscribe(q.msg_type, topic, self._forwarder(topic),
                                q.volatile_subscriber(C.RECORD_DEPTH)
                                if topic == T.JOINT_COMMANDS else q.subscriber(C.RECORD_DEPTH))
        self.announcer = ParamAnnouncer(self, 1e-3)  # its own parameters, at tick 0
        self.log.info(f"Foxglove WebSocket server on ws://{host}:{self.port} "
                      f"({len(self.channels)} topics)")

    def _forwarder(self, topic: str):  # type: ignore[no-untyped-def]
        channel = self.channels[topic]
        stamped = topic in STAMPED
        signed = topic in SIGNED_TOPICS

        def cb(data: bytes) -> None:
            if signed:  # authenticated, trailer stripped (Foxglove gets plain CDR)
                payload = self.guard.payload(topic, data)
                if payload is None:
                    return
                data = payload
            if stamped:
                stamp = C.decode_stamp(data)
                if topic == T.CLOCK and stamp > self.clock_ns:
                    self.clock_ns = stamp
                    self.server.broadcast_time(stamp)
            elif topic == T.MARKERS:
                stamp = marker_stamp(data) or self.clock_ns
            else:
                stamp = self.clock_ns
            channel.log(bytes(data), log_time=stamp)
            self.sent += 1
        return cb

    def close(self) -> None:
        """Stop the server."""
        self.server.stop()
        self.log.info(f"Foxglove server stopped ({self.sent} messages forwarded)")


def _finish(node: FoxgloveBridge, code: int) -> int:
    node.close()
    return code


def main(args: list[str] | None = None) -> int:
    """Entry point of ``foxglove_bridge``."""
    return run_node("foxglove_bridge", FoxgloveBridge, args, finish=_finish)


if __name__ == "__main__":
    sys.exit(main())
