"""Where messages meet arrays: the only module of the nodes that knows message layouts.

Two ways across the boundary:

* typed messages for the low-rate topics (status, indices, active controller, ...):
  :func:`joint_state`, :func:`clock`, :func:`diagnostic_array`, ...
* serialized CDR bytes for the per-tick topics, through the one ROS-free codec
  (``core/cdr.py``, re-exported here: :class:`JointStateCodec`, :data:`CODECS`, ...): the
  nodes publish and take raw bytes, the very bytes rclpy produces (XCDR1 little endian,
  padding zeroed); tests compare them.

:data:`TOPIC_QOS` gives rclpy profiles and message classes for the one topic table
(``core/topics.py`` ``TOPICS``, which the recorder and ``simulate --bag`` read too).
Stamps are integer nanoseconds of simulated time (``hexapod_common.core.topics.stamp_ns``).
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

from hexapod_common.core import cdr
from hexapod_common.core import topics as T
from ..core.cdr import (
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

#: Queue depths (topics.py): publishers' histories, the recorder's and the control loop's.
HISTORY_DEPTH, RECORD_DEPTH, CONTROL_DEPTH = T.HISTORY_DEPTH, T.RECORD_DEPTH, T.CONTROL_DEPTH
#: Message classes of the topic table's types.
MSG_CLASSES: dict[str, type] = {
    "rosgraph_msgs/msg/Clock": Clock, T.JOINT_STATE: JointState, "std_msgs/msg/String": String,
    T.DIAGNOSTIC_ARRAY: DiagnosticArray, "visualization_msgs/msg/MarkerArray": MarkerArray,
}


def _qos(depth: int, transient: bool = False) -> QoSProfile:
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=(DurabilityPolicy.TRANSIENT_LOCAL if transient
                                  else DurabilityPolicy.VOLATILE))


@dataclass(frozen=True)
class TopicQos:
    """rclpy's view of one row of the topic table (``topics.TOPICS``)."""

    spec: T.TopicSpec

    @property
    def msg_type(self) -> type:
        """The message class."""
        return MSG_CLASSES[self.spec.msg_type]

    @property
    def transient(self) -> bool:
        """Transient-local durability."""
        return self.spec.transient

    @property
    def depth(self) -> int:
        """The publisher's history depth."""
        return self.spec.depth

    @property
    def preset(self) -> str:
        """The bag's QoS preset ('reliable' or 'transient_local')."""
        return self.spec.preset

    def publisher(self) -> QoSProfile:
        """The publisher's profile."""
        return _qos(self.spec.depth, self.spec.transient)

    def subscriber(self, depth: int) -> QoSProfile:
        """A subscriber profile of ``depth`` that gets late-joiner history if offered."""
        return _qos(depth, self.spec.transient)

    def volatile_subscriber(self, depth: int) -> QoSProfile:
        """A volatile subscriber profile of ``depth``: matches transient-local and volatile
        writers alike (no late-joiner history)."""
        return _qos(depth, False)


#: The topic table with rclpy's QoS profiles and message classes.
TOPIC_QOS: dict[str, TopicQos] = {t: TopicQos(spec) for t, spec in T.TOPICS.items()}
#: /hexapod/recorded (the recorder's progress; not in the recorded table).
RECORDED_QOS = TopicQos(T.RECORDED_SPEC)

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


def encode_statuses(stamp_ns: int, statuses: Sequence[Status]) -> bytes:
    """The serialized DiagnosticArray of :func:`diagnostic_array` (the same bytes as rclpy's
    ``serialize_message``), through the project's CDR codec: ~10x faster, which matters
    for the messages a realtime node sends between ticks (status, parameter records)."""
    return cdr.encode_diagnostic_array(stamp_ns, [cdr.DiagnosticStatus(
        s.name, s.message, s.hardware_id, LEVELS[s.level],
        tuple((str(k), str(v)) for k, v in s.values.items())) for s in statuses])


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
    "MSG_CLASSES", "JointStateView", "LEVELS", "NS", "RECORD_DEPTH", "Status", "TOPIC_QOS",
    "TopicQos", "clock", "decode_stamp", "decode_string", "diagnostic_array",
    "encode_clock", "encode_string", "fill_obs", "from_time", "joint_state",
    "statuses", "string", "tick_of", "to_time",
]
