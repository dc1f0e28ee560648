"""Where messages meet arrays: the only module of the nodes that knows message layouts.

Two ways across the boundary:

* typed messages for the low-rate topics (status, indices, active controller, ...):
  :func:`joint_state`, :func:`columns`, :func:`clock`, :func:`diagnostic_array`, ...
* serialized CDR bytes for the per-tick topics: :class:`JointStateCodec` encodes and decodes
  ``sensor_msgs/JointState`` straight from and into float arrays (a few microseconds,
  against ~15 us for ``serialize_message`` and ~30 us for ``deserialize_message`` per
  message here), and the nodes publish and take raw bytes. The bytes are those rclpy
  produces (XCDR1 little endian, padding zeroed); tests compare them.

:data:`TOPIC_QOS` gives rclpy profiles and message classes for the one topic table
(``core/topics.py`` ``TOPICS``, which the recorder and ``simulate --bag`` read too).
Stamps are integer nanoseconds of simulated time (``hexapod_sim.core.topics.stamp_ns``).
"""
from __future__ import annotations

import struct
from dataclasses import dataclass
from functools import lru_cache
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

NS = 1_000_000_000
ENCAPSULATION = b"\x00\x01\x00\x00"  # CDR little endian, what rclpy writes first
_U32 = struct.Struct("<I")
_STAMP = struct.Struct("<iI")

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


#: The topic table with rclpy's QoS profiles and message classes.
TOPIC_QOS: dict[str, TopicQos] = {t: TopicQos(spec) for t, spec in T.TOPICS.items()}

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


def columns(msg: JointState) -> T.Columns:
    """Columns of a JointState (arrays copied out of the message)."""
    return T.Columns(tuple(msg.name), np.array(msg.position, dtype=float),
                     np.array(msg.velocity, dtype=float), np.array(msg.effort, dtype=float))


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


def _cdr_string(out: bytearray, text: str) -> None:
    out += b"\x00" * (-(len(out) - 4) % 4)
    raw = text.encode()
    out += _U32.pack(len(raw) + 1)
    out += raw
    out += b"\x00"


def encode_clock(stamp_ns: int) -> bytes:
    """Serialized rosgraph_msgs/Clock."""
    return ENCAPSULATION + _STAMP.pack(*divmod(int(stamp_ns), NS))


def decode_stamp(data: bytes) -> int:
    """Stamp (ns) of a serialized Clock or of any message starting with a std_msgs/Header."""
    sec, nsec = _STAMP.unpack_from(data, 4)
    return sec * NS + nsec


def encode_string(text: str) -> bytes:
    """Serialized std_msgs/String."""
    out = bytearray(ENCAPSULATION)
    _cdr_string(out, text)
    return bytes(out)


def decode_string(data: bytes) -> str:
    """Text of a serialized std_msgs/String."""
    (n,) = _U32.unpack_from(data, 4)
    return bytes(data[8:8 + n - 1]).decode()


class JointStateLayout(NamedTuple):
    """Constant bytes and value offsets of a JointState with given frame_id and names."""

    head: bytes        # frame_id, names and position count: from the stamp to the values
    gap: tuple[bytes, bytes]  # count + alignment before velocity and before effort
    offsets: tuple[int, int, int]    # byte offsets of the first value of each array
    size: int


@lru_cache(maxsize=64)
def joint_state_layout(frame_id: str, names: tuple[str, ...]) -> JointStateLayout:
    """Layout of a JointState whose three arrays have one value per name."""
    out = bytearray(12)  # encapsulation + stamp
    _cdr_string(out, frame_id)
    out += b"\x00" * (-(len(out) - 4) % 4)
    out += _U32.pack(len(names))
    for name in names:
        _cdr_string(out, name)
    pos = len(out)
    gaps, offsets = [], []
    for _ in range(3):
        gap = bytearray(b"\x00" * (-(pos - 4) % 4))  # CDR aligns relative to byte 4
        gap += _U32.pack(len(names))
        gap += b"\x00" * (-(pos + len(gap) - 4) % 8)
        pos += len(gap)
        gaps.append(bytes(gap))
        offsets.append(pos)
        pos += 8 * len(names)
    return JointStateLayout(bytes(out[12:]) + gaps[0], (gaps[1], gaps[2]),
                            (offsets[0], offsets[1], offsets[2]), pos)


def _parse_joint_state(data: bytes) -> tuple[int, str, tuple[str, ...], list[np.ndarray]]:
    """Generic (slow) parse of a serialized JointState, ignoring padding bytes."""
    try:
        pos = 4
        sec, nsec = _STAMP.unpack_from(data, pos)
        pos += 8

        def text() -> str:
            nonlocal pos
            pos += -(pos - 4) % 4
            (n,) = _U32.unpack_from(data, pos)
            s = bytes(data[pos + 4:pos + 4 + max(n - 1, 0)]).decode()
            pos += 4 + n
            return s

        frame_id = text()
        pos += -(pos - 4) % 4
        (count,) = _U32.unpack_from(data, pos)
        pos += 4
        names = tuple(text() for _ in range(count))
        arrays = []
        for _ in range(3):
            pos += -(pos - 4) % 4
            (n,) = _U32.unpack_from(data, pos)
            pos += 4
            if n:
                pos += -(pos - 4) % 8
            if pos + 8 * n > len(data):
                raise ValueError("array runs past the end")
            arrays.append(np.frombuffer(data, "<f8", n, pos))
            pos += 8 * n
    except (struct.error, UnicodeDecodeError, ValueError) as err:
        raise ValueError(f"not a serialized JointState: {err}") from err
    return sec * NS + nsec, frame_id, names, arrays


class JointStateView(NamedTuple):
    """A decoded JointState: stamp (ns), frame_id and read-only arrays into the message."""

    stamp_ns: int
    frame_id: str
    position: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray


class JointStateCodec:
    """Encode/decode serialized JointStates of one topic (fixed joint names) without rclpy.

    Decoding compares the message's size and constant bytes (names, counts) with the
    layout expected for its frame_id length; a message that differs (say, non-zero
    padding from another serializer) takes a generic parse, and one that does not carry
    this topic's joints with all three arrays filled raises ValueError.
    """

    def __init__(self, names: Sequence[str]) -> None:
        self.names = tuple(names)
        self.n = len(self.names)
        self._by_frame_len: dict[int, JointStateLayout] = {}

    def encode(self, stamp_ns: int, frame_id: str, position: np.ndarray, velocity: np.ndarray,
               effort: np.ndarray) -> bytes:
        """Serialized JointState (float64 arrays of length ``len(names)``)."""
        lay = joint_state_layout(frame_id, self.names)
        g1, g2 = lay.gap
        return b"".join((ENCAPSULATION, _STAMP.pack(*divmod(int(stamp_ns), NS)), lay.head,
                         np.ascontiguousarray(position, dtype="<f8").tobytes(),
                         g1, np.ascontiguousarray(velocity, dtype="<f8").tobytes(),
                         g2, np.ascontiguousarray(effort, dtype="<f8").tobytes()))

    def decode(self, data: bytes) -> JointStateView:
        """Stamp, frame_id and arrays (views into ``data``) of a serialized JointState."""
        (flen,) = _U32.unpack_from(data, 12)
        frame_id = bytes(data[16:16 + flen - 1]).decode() if flen else ""
        lay = self._by_frame_len.get(flen)
        if lay is None:
            lay = self._by_frame_len[flen] = joint_state_layout(frame_id, self.names)
        o0, o1, o2 = lay.offsets
        n = self.n
        start = 16 + flen  # the frame_id's bytes vary; the rest up to the values does not
        if (len(data) == lay.size and data[start:o0] == lay.head[start - 12:]
                and data[o1 - len(lay.gap[0]):o1] == lay.gap[0]
                and data[o2 - len(lay.gap[1]):o2] == lay.gap[1]):
            sec, nsec = _STAMP.unpack_from(data, 4)
            return JointStateView(sec * NS + nsec, frame_id, np.frombuffer(data, "<f8", n, o0),
                                  np.frombuffer(data, "<f8", n, o1),
                                  np.frombuffer(data, "<f8", n, o2))
        stamp, frame_id, names, arrays = _parse_joint_state(data)
        if names != self.names or any(len(a) != n for a in arrays):
            raise ValueError(f"JointState does not carry the {n} joints {self.names[0]}.."
                             f"{self.names[-1]} with all three arrays filled")
        return JointStateView(stamp, frame_id, arrays[0], arrays[1], arrays[2])


#: One codec per JointState topic of the contract.
CODECS: dict[str, JointStateCodec] = {
    T.JOINT_STATES: JointStateCodec(T.JOINT_NAMES),
    T.FOOT_FORCES: JointStateCodec(T.FOOT_NAMES),
    T.HIP_STATES: JointStateCodec(T.HIP_NAMES),
    T.REFERENCE: JointStateCodec(T.REFERENCE_NAMES),
    T.JOINT_COMMANDS: JointStateCodec(T.JOINT_NAMES),
}


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
    "MSG_CLASSES", "JointStateLayout", "JointStateView", "LEVELS", "NS", "RECORD_DEPTH",
    "Status", "TOPIC_QOS",
    "TopicQos", "clock", "columns", "decode_stamp", "decode_string", "diagnostic_array",
    "encode_clock", "encode_string", "fill_obs", "from_time", "joint_state",
    "joint_state_layout", "statuses", "string", "tick_of", "to_time",
]
