"""Where messages meet arrays: the only module of the nodes that knows message layouts.

Two ways across the boundary:

* typed messages for the low-rate topics (status, indices, active controller, ...):
  :func:`joint_state`, :func:`clock`, :func:`diagnostic_array`, ...
* serialized CDR bytes for the per-tick topics, through the one ROS-free codec
  (``core/cdr.py``, re-exported here: :class:`JointStateCodec`, :data:`CODECS`, ...): the
  nodes publish and take raw bytes, the very bytes rclpy produces (XCDR1 little endian,
  padding zeroed); tests compare them.

The QoS of each contract topic is defined here too (:data:`TOPIC_QOS`), so that publishers,
subscribers and the recorder agree. Stamps are integer nanoseconds of simulated time
(``hexapod_sim.core.topics.stamp_ns``).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, NamedTuple, Sequence

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from visualization_msgs.msg import MarkerArray

from .core import topics as T
from .core.cdr import (
    CODECS,
    ENCAPSULATION,
    NS,
    JointStateCodec,
    JointStateView,
    decode_stamp,
    decode_string,
    encode_clock,
    encode_string,
)

# --------------------------------------------------------------------------- QoS

#: Depth of the publishers' histories of the per-tick topics: how far (in ticks) a slow
#: reliable reader (the recorder) may lag before the writer drops samples for it.
HISTORY_DEPTH = 5000
#: Depth of the recorder's subscriptions (reader-side queue between two takes).
RECORD_DEPTH = 10000
#: Depth of the control loop's subscriptions (sim, controllers, trajectory generator,
#: markers): a process starved of CPU for up to this many ticks (0.2 s at 1 kHz), or a
#: topic flooded by a process outside the graph (whose messages are dropped, but fill the
#: queue first), still finds every message it needs. With 10, a controller taking over in
#: realtime mode on a loaded machine sometimes found the switch tick's state or inputs
#: rolled out of its queues and never answered it.
CONTROL_DEPTH = 200


def _qos(depth: int, transient: bool = False) -> QoSProfile:
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=(DurabilityPolicy.TRANSIENT_LOCAL if transient
                                  else DurabilityPolicy.VOLATILE))


@dataclass(frozen=True)
class TopicQos:
    """Offered (publisher) QoS of one contract topic; ``transient`` = transient-local.

    Reference and commands are transient-local so that a reader matched a little late (at
    start, or a controller or recorder started mid-run) still gets the recent samples.
    """

    msg_type: type
    transient: bool = False
    depth: int = HISTORY_DEPTH

    def publisher(self) -> QoSProfile:
        """The publisher's profile."""
        return _qos(self.depth, self.transient)

    def subscriber(self, depth: int) -> QoSProfile:
        """A subscriber profile of ``depth`` that gets late-joiner history if offered."""
        return _qos(depth, self.transient)

    @property
    def preset(self) -> str:
        """The bag writer's QoS preset for this topic ('reliable' or 'transient_local')."""
        return "transient_local" if self.transient else "reliable"


TOPIC_QOS: dict[str, TopicQos] = {
    T.CLOCK: TopicQos(Clock),
    T.JOINT_STATES: TopicQos(JointState),
    T.FOOT_FORCES: TopicQos(JointState),
    T.HIP_STATES: TopicQos(JointState),
    T.REFERENCE: TopicQos(JointState, transient=True),
    T.JOINT_COMMANDS: TopicQos(JointState, transient=True),
    T.ACTIVE_CONTROLLER: TopicQos(String, transient=True, depth=1),
    T.INDICES: TopicQos(DiagnosticArray, depth=100),
    T.STATUS: TopicQos(DiagnosticArray, depth=10),
    T.MARKERS: TopicQos(MarkerArray, depth=100),
    T.PARAMETERS: TopicQos(DiagnosticArray, transient=True, depth=1000),
}

# --------------------------------------------------------------------------- stamps


def to_time(stamp_ns: int) -> Time:
    """Integer nanoseconds -> builtin_interfaces/Time."""
    sec, nsec = divmod(int(stamp_ns), NS)
    return Time(sec=sec, nanosec=nsec)


def from_time(t: Time) -> int:
    """builtin_interfaces/Time -> integer nanoseconds."""
    return int(t.sec) * NS + int(t.nanosec)


def tick_of(stamp_ns: int, period_ns: int) -> int:
    """Tick index of a stamp (stamps are k * control period, rounded to ns)."""
    return (int(stamp_ns) + period_ns // 2) // period_ns


# --------------------------------------------------------------------------- typed messages


def joint_state(cols: T.Columns, stamp_ns: int, frame_id: str = "") -> JointState:
    """A JointState from columns (all three arrays filled, see topics.py)."""
    msg = JointState()
    msg.header.stamp = to_time(stamp_ns)
    msg.header.frame_id = frame_id
    msg.name = list(cols.names)
    msg.position = np.asarray(cols.position, dtype=float).tolist()
    msg.velocity = np.asarray(cols.velocity, dtype=float).tolist()
    msg.effort = np.asarray(cols.effort, dtype=float).tolist()
    return msg


def clock(stamp_ns: int) -> Clock:
    """A rosgraph_msgs/Clock."""
    return Clock(clock=to_time(stamp_ns))


def string(text: str) -> String:
    """A std_msgs/String."""
    return String(data=text)


#: diagnostic_msgs/DiagnosticStatus levels (a ``byte`` field: bytes of length 1 in rclpy).
LEVELS = {"ok": 0, "warn": 1, "error": 2, "stale": 3}


class Status(NamedTuple):
    """One diagnostic status as plain data; ``level`` is a key of :data:`LEVELS`."""

    name: str
    level: str
    message: str
    values: Mapping[str, str]
    hardware_id: str = "hexapod"


def diagnostic_array(stamp_ns: int, statuses: Sequence[Status]) -> DiagnosticArray:
    """A DiagnosticArray of ``statuses`` stamped ``stamp_ns``."""
    msg = DiagnosticArray()
    msg.header.stamp = to_time(stamp_ns)
    for s in statuses:
        st = DiagnosticStatus(level=bytes((LEVELS[s.level],)), name=s.name, message=s.message,
                              hardware_id=s.hardware_id)
        st.values = [KeyValue(key=str(k), value=str(v)) for k, v in s.values.items()]
        msg.status.append(st)
    return msg


def statuses(msg: DiagnosticArray) -> list[Status]:
    """Inverse of :func:`diagnostic_array`."""
    names = {v: k for k, v in LEVELS.items()}
    out = []
    for st in msg.status:
        level = st.level if isinstance(st.level, int) else int.from_bytes(st.level, "little")
        out.append(Status(st.name, names.get(level, str(level)), st.message,
                          {kv.key: kv.value for kv in st.values}, st.hardware_id))
    return out


# --------------------------------------------------------------------------- raw CDR
# The per-tick topics travel as raw CDR bytes, through the project's one codec
# (core/cdr.py, ROS-free, shared with the bag code): CODECS, encode_clock, decode_stamp, ...


def fill_obs(obs: np.ndarray, topic: str, position: np.ndarray, velocity: np.ndarray,
             effort: np.ndarray) -> None:
    """Write one state topic's arrays into their rows of an observation (9, 6, 2)."""
    _, (rp, rv, re) = T.STATE_TOPICS[topic]
    shape = obs.shape[1:]
    obs[rp] = position.reshape(shape)
    obs[rv] = velocity.reshape(shape)
    obs[re] = effort.reshape(shape)


__all__ = [
    "CODECS", "CONTROL_DEPTH", "ENCAPSULATION", "HISTORY_DEPTH", "JointStateCodec",
    "JointStateView", "LEVELS", "NS", "RECORD_DEPTH", "Status", "TOPIC_QOS",
    "TopicQos", "clock", "decode_stamp", "decode_string", "diagnostic_array",
    "encode_clock", "encode_string", "fill_obs", "from_time", "joint_state",
    "statuses", "string", "tick_of", "to_time",
]
