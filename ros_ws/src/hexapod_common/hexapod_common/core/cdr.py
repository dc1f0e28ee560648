"""Little-endian CDR (XCDR1, encapsulation ``00 01 00 00``): the project's one codec.

ROS-free, so that the node shells (per-tick raw publish and take, :class:`JointStateCodec`)
and the bag code of ``hexapod_metrics`` (the vectorised :class:`JointStateDecoder`) import it
downward. Failures raise :class:`~hexapod_common.core.errors.CdrError` (a ``ValueError``).

Encoders produce exactly the bytes rclpy's ``serialize_message`` produces (Fast-CDR), except
that our padding bytes are always zero while rclpy leaves them uninitialised (tests compare
everything but the padding). One Fast-CDR quirk is reproduced on purpose: an empty
``float64[]`` is not aligned, but rclpy's message length is Fast-CDR's size estimate, which
aligns it anyway, so the message ends with 4 or 8 spare bytes. ``rosbags`` rejects such a
message ("CDR message size mismatch"); JointStates therefore always carry all three arrays
(``BagWriter.write_joint_state`` insists), and our decoder accepts the spare bytes.

The vectorised JointState decoder works on many messages of one topic: messages of one size
share a layout (names, array lengths and the padded frame_id length), so the field offsets
are computed once, every message is one row of a 2-D byte array (a strided view into the
chunk when evenly spaced) and the constant bytes of all rows (encapsulation, names, counts)
are checked with one masked compare. Rows that do not match are decoded one by one.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Sequence
from functools import lru_cache
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from hexapod_common.core import topics as T
from .errors import CdrError

__all__ = [
    'CODECS',
    'ENCAPSULATION',
    'CommandCodec',
    'MAX_DDS_PADDING',
    'DiagnosticStatus',
    'JointStateArrays',
    'JointStateCodec',
    'JointStateDecoder',
    'JointStateLayout',
    'JointStateMsg',
    'JointStateView',
    'cdr_padding_mask',
    'decode_clock',
    'decode_diagnostic_array',
    'decode_joint_state',
    'decode_joint_state_batch',
    'decode_joint_state_row',
    'decode_joint_state_rows',
    'decode_stamp',
    'decode_string',
    'encode_clock',
    'encode_diagnostic_array',
    'encode_joint_state',
    'encode_string',
    'gather_rows',
    'joint_state_layout',
]

ENCAPSULATION = b'\x00\x01\x00\x00'
"""CDR_LE, no options: what rclpy writes in front of every message."""
MAX_DDS_PADDING = 3
"""Zero bytes DDS may append to a serialized payload (up to a multiple of 4 bytes)."""

NS = 1_000_000_000
"""Nanoseconds per second (stamps are integer ns)."""
_NS = NS
_U32 = struct.Struct('<I')
_STAMP = struct.Struct('<iI')

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]
ByteArray = npt.NDArray[np.uint8]


class JointStateMsg(NamedTuple):
    """One decoded ``sensor_msgs/msg/JointState``."""

    stamp_ns: int
    frame_id: str
    names: tuple[str, ...]
    position: FloatArray
    velocity: FloatArray
    effort: FloatArray


class JointStateArrays(NamedTuple):
    """Many JointStates of one topic: ``stamps`` (N,) ns, arrays (N, k)."""

    stamps: IntArray
    names: tuple[str, ...]
    position: FloatArray
    velocity: FloatArray
    effort: FloatArray


class DiagnosticStatus(NamedTuple):
    """One ``diagnostic_msgs/msg/DiagnosticStatus`` (level 0 OK, 1 WARN, 2 ERROR, 3 STALE)."""

    name: str
    message: str = ''
    hardware_id: str = ''
    level: int = 0
    values: tuple[tuple[str, str], ...] = ()


# --------------------------------------------------------------------------- encoding


def _split_stamp(stamp_ns: int) -> tuple[int, int]:
    sec, nsec = divmod(int(stamp_ns), _NS)
    return sec, nsec


def _pad(offset: int, align: int) -> int:
    """Padding needed at CDR data offset ``offset`` (encapsulation excluded)."""
    return -offset % align


def _string(out: bytearray, text: str) -> None:
    """Append a CDR string (aligned u32 length incl. NUL, bytes, NUL)."""
    out += b'\x00' * _pad(len(out) - 4, 4)
    raw = text.encode()
    out += _U32.pack(len(raw) + 1)
    out += raw
    out += b'\x00'


@lru_cache(maxsize=256)
def _joint_state_plan(
    frame_id: str,
    names: tuple[str, ...],
    sizes: tuple[int, int, int],
) -> tuple[bytes, bytes, bytes, bytes, bytes]:
    """Constant pieces of a JointState around its stamp and three arrays (cached).

    Returns (frame_id and names, gap before position, before velocity, before effort,
    tail): a gap is the array count and its alignment padding. Like Fast-CDR, an empty
    ``float64[]`` is not aligned but still counted as aligned in the message length,
    which rclpy pads with trailing bytes (``tail``).
    """
    out = bytearray(12)  # encapsulation + stamp placeholder keep the offsets right
    _string(out, frame_id)
    out += b'\x00' * _pad(len(out) - 4, 4)
    out += _U32.pack(len(names))
    for name in names:
        _string(out, name)
    out += b'\x00' * _pad(len(out) - 4, 4)
    real = est = len(out) - 4  # CDR data offsets: real, and Fast-CDR's size estimate
    gaps = []
    for size in sizes:
        gap = _U32.pack(size)
        real += 4
        est += 4 + _pad(est + 4, 8)
        if size:
            pad = _pad(real, 8)
            gap += b'\x00' * pad
            real += pad + 8 * size
            est += 8 * size
        gaps.append(gap)
    return bytes(out[12:]), gaps[0], gaps[1], gaps[2], b'\x00' * (est - real)


def _f64(values: Sequence[float] | FloatArray) -> bytes:
    return np.asarray(values, dtype='<f8').tobytes()


def encode_joint_state(
    stamp_ns: int,
    names: Sequence[str],
    position: Sequence[float] | FloatArray,
    velocity: Sequence[float] | FloatArray,
    effort: Sequence[float] | FloatArray,
    frame_id: str = '',
) -> bytes:
    """Serialize a ``sensor_msgs/msg/JointState`` like rclpy does (padding zeroed)."""
    pos, vel, eff = _f64(position), _f64(velocity), _f64(effort)
    sizes = (len(pos) // 8, len(vel) // 8, len(eff) // 8)
    middle, gap_p, gap_v, gap_e, tail = _joint_state_plan(frame_id, tuple(names), sizes)
    stamp = _STAMP.pack(*divmod(int(stamp_ns), _NS))
    return b''.join((ENCAPSULATION, stamp, middle, gap_p, pos, gap_v, vel, gap_e, eff, tail))


def encode_string(data: str) -> bytes:
    """Serialize a ``std_msgs/msg/String``."""
    out = bytearray(ENCAPSULATION)
    _string(out, data)
    return bytes(out)


def encode_clock(stamp_ns: int) -> bytes:
    """Serialize a ``rosgraph_msgs/msg/Clock``."""
    return ENCAPSULATION + _STAMP.pack(*_split_stamp(stamp_ns))


def encode_diagnostic_array(
    stamp_ns: int,
    statuses: Sequence[DiagnosticStatus],
    frame_id: str = '',
) -> bytes:
    """Serialize a ``diagnostic_msgs/msg/DiagnosticArray``."""
    out = bytearray(ENCAPSULATION)
    out += _STAMP.pack(*_split_stamp(stamp_ns))
    _string(out, frame_id)
    out += b'\x00' * _pad(len(out) - 4, 4)
    out += _U32.pack(len(statuses))
    for status in statuses:
        out += bytes((int(status.level) & 0xFF,))
        _string(out, status.name)
        _string(out, status.message)
        _string(out, status.hardware_id)
        out += b'\x00' * _pad(len(out) - 4, 4)
        out += _U32.pack(len(status.values))
        for key, value in status.values:
            _string(out, key)
            _string(out, value)
    return bytes(out)


# --------------------------------------------------------------------------- slow decoding


class _Reader:
    """Sequential CDR reader over one message; optionally records padding bytes."""

    def __init__(
        self,
        data: bytes | memoryview,
        mask: bytearray | None = None,
        errors: str = 'replace',
    ) -> None:
        self.data = memoryview(data)
        self.errors = errors  # how invalid UTF-8 in strings is handled (str.decode)
        if len(self.data) < 4 or bytes(self.data[:2]) != b'\x00\x01':
            msg = f'not little-endian CDR (encapsulation {bytes(self.data[:4]).hex(" ")!r})'
            raise CdrError(msg)
        self.pos = 4
        self.mask = mask
        self.phantom = 0  # Fast-CDR size estimate minus real size, see f64_seq
        self.seq_start = 0

    def need(self, size: int) -> None:
        if self.pos + size > len(self.data):
            msg = f'CDR message too short: need {self.pos + size} bytes, have {len(self.data)}'
            raise CdrError(msg)

    def skip(self, size: int) -> None:
        self.need(size)
        self.pos += size

    def align(self, size: int) -> None:
        pad = _pad(self.pos - 4, size)
        self.phantom += _pad(self.pos - 4 + self.phantom, size) - pad
        self.need(pad)
        if self.mask is not None:
            self.mask[self.pos:self.pos + pad] = b'\x01' * pad
        self.pos += pad

    def u8(self) -> int:
        self.need(1)
        self.pos += 1
        return int(self.data[self.pos - 1])

    def u32(self) -> int:
        self.align(4)
        self.need(4)
        (value,) = _U32.unpack_from(self.data, self.pos)
        self.pos += 4
        return int(value)

    def stamp(self) -> int:
        self.align(4)
        self.need(8)
        sec, nsec = _STAMP.unpack_from(self.data, self.pos)
        self.pos += 8
        return int(sec) * _NS + int(nsec)

    def string(self) -> str:
        size = self.u32()
        self.need(size)
        raw = bytes(self.data[self.pos:self.pos + size])
        self.pos += size
        return raw[:-1].decode(errors=self.errors) if size else ''

    def f64_seq(self) -> FloatArray:
        """Read a float64[]; an empty one is not aligned but counts in Fast-CDR's estimate."""
        count = self.u32()
        if count:
            self.align(8)
        else:
            self.phantom += _pad(self.pos - 4 + self.phantom, 8)
        self.seq_start = self.pos
        self.need(8 * count)
        arr = np.frombuffer(self.data, dtype='<f8', count=count, offset=self.pos).astype(
            np.float64,
        )
        self.pos += 8 * count
        return arr

    def end(self) -> None:
        """Check the size: rclpy's length is Fast-CDR's estimate, up to 8 bytes too long,
        and DDS pads a serialized payload with up to 3 zero bytes to a multiple of 4."""
        extra = len(self.data) - self.pos
        padded = 0 < extra <= MAX_DDS_PADDING and not any(self.data[self.pos:])
        if extra not in (0, self.phantom) and not padded:
            msg = f'CDR message has {extra} unexpected trailing bytes'
            raise CdrError(msg)
        if self.mask is not None:
            self.mask[self.pos:] = b'\x01' * extra


def _decode_joint_state(rd: _Reader) -> JointStateMsg:
    stamp = rd.stamp()
    frame_id = rd.string()
    names = tuple(rd.string() for _ in range(rd.u32()))
    pos, vel, eff = rd.f64_seq(), rd.f64_seq(), rd.f64_seq()
    rd.end()
    return JointStateMsg(stamp, frame_id, names, pos, vel, eff)


def _decode_string(rd: _Reader) -> str:
    text = rd.string()
    rd.end()
    return text


def _decode_clock(rd: _Reader) -> int:
    stamp = rd.stamp()
    rd.end()
    return stamp


def _decode_diagnostic_array(rd: _Reader) -> tuple[int, list[DiagnosticStatus]]:
    stamp = rd.stamp()
    rd.string()  # frame_id
    statuses = []
    for _ in range(rd.u32()):
        level = rd.u8()
        name, message, hardware_id = rd.string(), rd.string(), rd.string()
        values = tuple((rd.string(), rd.string()) for _ in range(rd.u32()))
        statuses.append(DiagnosticStatus(name, message, hardware_id, level, values))
    rd.end()
    return stamp, statuses


def decode_joint_state(data: bytes | memoryview) -> JointStateMsg:
    """Decode one ``sensor_msgs/msg/JointState`` (the slow reference path)."""
    return _decode_joint_state(_Reader(data))


def decode_string(data: bytes | memoryview) -> str:
    """Decode one ``std_msgs/msg/String``."""
    return _decode_string(_Reader(data))


def decode_clock(data: bytes | memoryview) -> int:
    """Decode one ``rosgraph_msgs/msg/Clock`` to nanoseconds."""
    return _decode_clock(_Reader(data))


def decode_diagnostic_array(data: bytes | memoryview) -> tuple[int, list[DiagnosticStatus]]:
    """Decode one ``diagnostic_msgs/msg/DiagnosticArray`` to (stamp ns, statuses)."""
    return _decode_diagnostic_array(_Reader(data))


def decode_stamp(data: bytes | memoryview) -> int:
    """Stamp (ns) of a serialized Clock or of any message that starts with a Header.

    Reads bytes 4-12 only (no check of the rest: a hot path for stamped topics)."""
    if len(data) < 12:
        msg = f'CDR message too short for a stamp: {len(data)} bytes'
        raise CdrError(msg)
    sec, nsec = _STAMP.unpack_from(data, 4)
    return int(sec) * _NS + int(nsec)


_PADDING_DECODERS: dict[str, Callable[[_Reader], object]] = {
    'sensor_msgs/msg/JointState': _decode_joint_state,
    'diagnostic_msgs/msg/DiagnosticArray': _decode_diagnostic_array,
    'std_msgs/msg/String': _decode_string,
    'rosgraph_msgs/msg/Clock': _decode_clock,
}


def cdr_padding_mask(data: bytes, msgtype: str) -> bytes:
    """Return a mask with 1 at every alignment-padding byte of ``data`` (for comparisons)."""
    mask = bytearray(len(data))
    _PADDING_DECODERS[msgtype](_Reader(data, mask))
    return bytes(mask)


# --------------------------------------------------------------------------- fast decoding


class JointStateLayout(NamedTuple):
    """Byte layout shared by the JointStates of one topic, taken from a first message.

    Offsets are in bytes of the serialized message (encapsulation header included).
    ``reference``/``mask`` cover the message prefix up to the first position value: the
    encapsulation, names and position count must equal ``reference`` wherever ``mask`` is
    set. Padding, stamp and
    frame_id are free: a frame_id of another length but the same padded length moves
    nothing (a longer one changes the size, hence the layout).
    """

    size: int
    names: tuple[str, ...]
    pos: int
    vel: int
    eff: int
    """Offsets of the first position, velocity and effort value."""
    reference: npt.NDArray[np.uint64]
    """The message prefix up to the first position value (8-byte words), where ``mask``
    is set."""
    mask: npt.NDArray[np.uint64]
    """0xFF at the constant bytes of the prefix (encapsulation, names, counts), else 0."""

    @property
    def prefix(self) -> int:
        """Length of the compared prefix (a multiple of 8)."""
        return 8 * len(self.mask)

    @property
    def k(self) -> int:
        """Number of joints."""
        return len(self.names)


def joint_state_layout(data: bytes | memoryview) -> JointStateLayout:
    """Compute the layout of a JointState whose three arrays all have one value per name."""
    size = len(data)
    pad = bytearray(size)
    rd = _Reader(data, pad)
    rd.stamp()
    frame_at = rd.pos
    rd.string()  # frame_id
    rd.align(4)
    names_at = rd.pos
    names = tuple(rd.string() for _ in range(rd.u32()))
    k = len(names)
    if not k:
        raise CdrError('JointState without joint names: nothing to decode into arrays')
    starts = []
    for _ in range(3):
        count = len(rd.f64_seq())
        if count != k:
            text = f'JointState array of length {count} for {k} joint names'
            raise CdrError(text)
        starts.append(rd.seq_start)
    rd.end()
    prefix = starts[0] + 4  # first position is 8-aligned in CDR, i.e. at 4 mod 8 here
    keep = np.where(np.frombuffer(pad, np.uint8)[:prefix] == 1, 0, 0xFF).astype(np.uint8)
    keep[4:12] = 0  # stamp
    keep[frame_at:names_at] = 0  # frame_id may vary within its padded length
    keep[starts[0]:] = 0
    mask = keep.view('<u8').copy()
    reference = np.frombuffer(data, '<u8', count=prefix // 8) & mask
    return JointStateLayout(size, names, starts[0], starts[1], starts[2], reference, mask)


def decode_joint_state_rows(
    buf: npt.NDArray[np.uint8],
    starts: IntArray,
    layout: JointStateLayout,
) -> tuple[BoolArray, IntArray, FloatArray, FloatArray, FloatArray]:
    """Decode the JointStates ``buf[starts[i]:starts[i] + layout.size]`` of one layout.

    Returns ``ok`` (n,), stamps (n,) and position, velocity, effort as (n, k) *views* into
    ``buf`` (strided when the messages are evenly spaced, else gathered copies); copy them
    out before ``buf`` goes away. Rows with ``ok == False`` have another layout and hold
    garbage: decode those one by one. The caller guarantees ``buf`` holds every message.
    """
    k = layout.k
    rows = gather_rows(buf, starts, layout.size)
    # numpy, not a compiled loop: a numba kernel is ~1.5x faster per row, but loading it
    # costs ~0.5 s of CPU per process, more than it saves on a 60 s bag (S6)
    diff = rows[:, :layout.prefix].view('<u8') & layout.mask
    diff ^= layout.reference
    ok = np.bitwise_or.reduce(diff, axis=1) == 0
    for at in (layout.vel, layout.eff):  # the two later counts (4 bytes before padding)
        ok &= rows[:, at - 8:at - 4].view('<u4')[:, 0] == k
    stamp = rows[:, 4:12].view('<i4')
    stamps = stamp[:, 0].astype(np.int64) * _NS + stamp[:, 1].view('<u4')
    views = [rows[:, at:at + 8 * k].view('<f8') for at in (layout.pos, layout.vel, layout.eff)]
    return ok, stamps, views[0], views[1], views[2]


def gather_rows(
    buf: npt.NDArray[np.uint8],
    starts: npt.NDArray[np.int64],
    width: int,
) -> npt.NDArray[np.uint8]:
    """Rows ``buf[s:s + width]`` for all ``starts``: a strided view if they are evenly
    spaced (no copy), else one fancy-indexed copy. ``buf`` must hold the last row fully."""
    n = len(starts)
    if n == 0:
        return np.zeros((0, width), np.uint8)
    first = int(starts[0])
    step = int(starts[1] - starts[0]) if n > 1 else 1
    if step > 0 and (n == 1 or bool((np.diff(starts) == step).all())):
        return np.lib.stride_tricks.as_strided(
            buf[first:], shape=(n, width), strides=(step, 1), writeable=False,
        )
    windows = np.ndarray(
        shape=(len(buf) - width + 1,),
        dtype=np.dtype((np.void, width)),
        buffer=buf,
        strides=(1,),
    )
    return windows[starts].view(np.uint8).reshape(n, width)


class JointStateDecoder:
    """Decodes the JointStates of one topic batch by batch, vectorised per message size.

    Messages of one size share a layout unless names, counts or frame_id length differ;
    the layout of each size is computed once from its first message and every row is
    verified against it. Rows that do not fit are decoded one by one; a message whose
    names differ from the topic's first message raises :class:`CdrError`.
    """

    def __init__(self) -> None:
        """Start without layouts; they are learnt from the messages."""
        self.layouts: dict[int, JointStateLayout | None] = {}
        self.names: tuple[str, ...] | None = None
        self.frame: str | None = None  # frame_id of the last message seen by frame_changes
        self.frame_log: list[tuple[int, str]] | None = None
        """Where the bag reader appends (stamp ns, frame_id) changes, if anyone asks."""

    def frame_changes(
        self, buf: ByteArray, starts: IntArray, sizes: IntArray,
    ) -> list[tuple[int, str]]:
        """(row, frame_id) of every message whose header.frame_id differs from the message
        before it (across calls), vectorised: rows whose frame bytes equal the previous
        row's are skipped with one compare; only candidate rows are decoded."""
        n = len(starts)
        if n == 0:
            return []
        if int(sizes.min()) < 16:
            msg = 'JointState shorter than its header'
            raise CdrError(msg)
        lengths = gather_rows(buf, starts + 12, 4).view('<u4')[:, 0].astype(np.int64)
        width = min(int(lengths.max()), int(sizes.min()) - 16)
        head = gather_rows(buf, starts + 12, 4 + width)
        candidates = np.flatnonzero(np.any(head[1:] != head[:-1], axis=1)) + 1
        out = []
        for i in (0, *candidates.tolist()):
            size = int(lengths[i])
            if 16 + size > int(sizes[i]):
                msg = f'JointState frame_id of {size} bytes runs past its message'
                raise CdrError(msg)
            at = int(starts[i]) + 16
            frame = bytes(buf[at:at + max(size - 1, 0)]).decode(errors='replace')
            if frame != self.frame:
                out.append((i, frame))
                self.frame = frame
        return out

    def _layout(self, size: int, message: bytes) -> JointStateLayout | None:
        if size not in self.layouts:
            try:
                layout: JointStateLayout | None = joint_state_layout(message)
            except CdrError:
                layout = None  # e.g. an empty array: such rows take the slow path
            if layout is not None and self.names is not None and layout.names != self.names:
                layout = None  # let the slow path report the change of names
            self.layouts[size] = layout
        return self.layouts[size]

    def decode(self, buf: ByteArray, starts: IntArray, sizes: IntArray) -> JointStateArrays:
        """Decode the messages ``buf[starts[i]:starts[i] + sizes[i]]`` (all in ``buf``).

        In the common case (one size, every row fits) the arrays are views into ``buf``.
        """
        first = int(sizes[0])
        if bool((sizes == first).all()):
            layout = self._layout(first, bytes(buf[starts[0]:starts[0] + first]))
            if layout is not None:
                ok, stamps, pos, vel, eff = decode_joint_state_rows(buf, starts, layout)
                if bool(ok.all()):
                    self.names = layout.names
                    return JointStateArrays(stamps, layout.names, pos, vel, eff)
        return self._decode_mixed(buf, starts, sizes)

    def _decode_mixed(self, buf: ByteArray, starts: IntArray, sizes: IntArray) -> JointStateArrays:
        n = len(starts)
        ok = np.zeros(n, bool)
        parts = []
        for size in np.unique(sizes):
            sel = np.flatnonzero(sizes == size)
            layout = self._layout(int(size), bytes(buf[starts[sel[0]]:starts[sel[0]] + size]))
            if layout is not None:
                good, *arrays = decode_joint_state_rows(buf, starts[sel], layout)
                ok[sel] = good
                parts.append((sel, arrays))
                self.names = self.names or layout.names
        if self.names is None:
            self.names = decode_joint_state(bytes(buf[starts[0]:starts[0] + sizes[0]])).names
        k = len(self.names)
        stamps = np.empty(n, np.int64)
        pos, vel, eff = np.empty((n, k)), np.empty((n, k)), np.empty((n, k))
        for sel, (st, p, v, e) in parts:
            stamps[sel], pos[sel], vel[sel], eff[sel] = st, p, v, e
        for i in np.flatnonzero(~ok):
            data = bytes(buf[starts[i]:starts[i] + sizes[i]])
            stamps[i], pos[i], vel[i], eff[i] = decode_joint_state_row(data, self.names)
        return JointStateArrays(stamps, self.names, pos, vel, eff)


def decode_joint_state_batch(messages: Sequence[bytes]) -> JointStateArrays:
    """Decode many serialized JointStates of one topic (fast path, per-message fallback)."""
    if not messages:
        empty = np.zeros((0, 0))
        return JointStateArrays(np.zeros(0, np.int64), (), empty, empty.copy(), empty.copy())
    sizes = np.fromiter((len(m) for m in messages), np.int64, len(messages))
    starts = np.zeros(len(messages), np.int64)
    np.cumsum(sizes[:-1], out=starts[1:])
    buf = np.frombuffer(b''.join(messages), np.uint8)
    stamps, names, *arrays = JointStateDecoder().decode(buf, starts, sizes)
    pos, vel, eff = (np.array(a) for a in arrays)  # own copies, not views into buf
    return JointStateArrays(stamps, names, pos, vel, eff)


def decode_joint_state_row(
    data: bytes | memoryview,
    names: tuple[str, ...],
) -> tuple[int, FloatArray, FloatArray, FloatArray]:
    """Slow path for one message that must carry ``names``; empty arrays become NaN."""
    msg = decode_joint_state(data)
    if msg.names != names:
        text = f'joint names changed within a topic: {list(names)} became {list(msg.names)}'
        raise CdrError(text)
    out = []
    for arr in (msg.position, msg.velocity, msg.effort):
        if len(arr) == len(names):
            out.append(arr)
        elif len(arr) == 0:
            out.append(np.full(len(names), np.nan))
        else:
            text = f'JointState array of length {len(arr)} for {len(names)} joint names'
            raise CdrError(text)
    return msg.stamp_ns, out[0], out[1], out[2]


# --------------------------------------------------------------------------- per-topic codec


class JointStateView(NamedTuple):
    """A decoded JointState: stamp (ns), frame_id and arrays (read-only views if fast)."""

    stamp_ns: int
    frame_id: str
    position: FloatArray
    velocity: FloatArray
    effort: FloatArray


class _Frame(NamedTuple):
    """Constant bytes and value offsets of a topic's JointState for one frame_id length."""

    head: bytes
    """From the end of the frame_id's length field + text to the first position value."""
    gaps: tuple[bytes, bytes]
    """Count and padding before the velocity and before the effort values."""
    offsets: tuple[int, int, int]
    size: int


class JointStateCodec:
    """Encode/decode the serialized JointStates of one topic (fixed joint names) per message.

    A few microseconds per message (against ~15 us for rclpy's ``serialize_message`` and
    ~30 us for ``deserialize_message``): the nodes publish and take raw bytes. Decoding
    compares the size and the constant bytes (names, counts) with the layout expected for
    the frame_id's length; any other message (non-zero padding, DDS padding, another
    serializer) takes the generic decoder, and one that does not carry this topic's joints
    with all three arrays filled raises :class:`CdrError` ("does not carry ...").
    """

    def __init__(self, names: Sequence[str]) -> None:
        """``names``: the topic's joint names, in message order."""
        self.names = tuple(names)
        self.n = len(self.names)
        self._frames: dict[int, _Frame] = {}

    def encode(
        self,
        stamp_ns: int,
        frame_id: str,
        position: Sequence[float] | FloatArray,
        velocity: Sequence[float] | FloatArray,
        effort: Sequence[float] | FloatArray,
    ) -> bytes:
        """Serialized JointState (float64 arrays of one value per name), as rclpy writes it."""
        return encode_joint_state(stamp_ns, self.names, position, velocity, effort, frame_id)

    def _frame(self, flen: int, frame_id: str) -> _Frame:
        middle, gap_p, gap_v, gap_e, _ = _joint_state_plan(frame_id, self.names, (self.n,) * 3)
        o0 = 12 + len(middle) + len(gap_p)
        o1 = o0 + 8 * self.n + len(gap_v)
        o2 = o1 + 8 * self.n + len(gap_e)
        return _Frame(middle[4 + flen:] + gap_p, (gap_v, gap_e), (o0, o1, o2), o2 + 8 * self.n)

    def decode(self, data: bytes, size: int | None = None) -> JointStateView:
        """Stamp, frame_id and arrays of a serialized JointState of this topic: the first
        ``size`` bytes of ``data`` (default all; the rest, e.g. an authentication trailer,
        is not looked at and nothing is copied)."""
        if size is None:
            size = len(data)
        elif size != len(data):
            size = min(size, len(data))
        try:
            (flen,) = _U32.unpack_from(data, 12)
            frame_id = bytes(data[16:min(16 + flen - 1, size)]).decode() if flen else ''
        except (struct.error, UnicodeDecodeError) as err:
            msg = f'not a serialized JointState: {err}'
            raise CdrError(msg) from err
        lay = self._frames.get(flen)
        if lay is None and 16 + flen <= size:
            lay = self._frames[flen] = self._frame(flen, frame_id)
        if lay is not None:
            o0, o1, o2 = lay.offsets
            gap_v, gap_e = lay.gaps
        if (lay is not None and size == lay.size and data[16 + flen:o0] == lay.head
                and data[:2] == ENCAPSULATION[:2]
                and data[o1 - len(gap_v):o1] == gap_v and data[o2 - len(gap_e):o2] == gap_e):
            sec, nsec = _STAMP.unpack_from(data, 4)
            n = self.n
            return JointStateView(sec * NS + nsec, frame_id, np.frombuffer(data, '<f8', n, o0),
                                  np.frombuffer(data, '<f8', n, o1),
                                  np.frombuffer(data, '<f8', n, o2))
        if size != len(data):
            data = data[:size]
        try:
            full = _decode_joint_state(_Reader(data, errors='strict'))
        except UnicodeDecodeError as err:
            text = f'not a serialized JointState: {err}'
            raise CdrError(text) from err
        arrays = (full.position, full.velocity, full.effort)
        if full.names != self.names or any(len(a) != self.n for a in arrays):
            text = (f'JointState does not carry the {self.n} joints {self.names[0]}..'
                    f'{self.names[-1]} with all three arrays filled')
            raise CdrError(text)
        return JointStateView(full.stamp_ns, full.frame_id, *arrays)


class CommandCodec:
    """The codec of /hexapod/joint_commands: a JointState of the 12 joints (torque-only) or
    of the 24 entries of a drive command (the joints, then ``<joint>/gains``;
    docs/controllers.md). The names count after the frame_id picks the form; each form
    decodes as :class:`JointStateCodec` does."""

    def __init__(self, names: Sequence[str], drive_names: Sequence[str]) -> None:
        self.torque = JointStateCodec(names)
        self.drive = JointStateCodec(drive_names)
        self.names = self.torque.names
        self.n = self.torque.n

    def encode(
        self,
        stamp_ns: int,
        frame_id: str,
        position: Sequence[float] | FloatArray,
        velocity: Sequence[float] | FloatArray,
        effort: Sequence[float] | FloatArray,
    ) -> bytes:
        """12 values per array: a torque-only command; 24: a drive command."""
        codec = self.drive if len(effort) == self.drive.n else self.torque
        return codec.encode(stamp_ns, frame_id, position, velocity, effort)

    def decode(self, data: bytes, size: int | None = None) -> JointStateView:
        """As :meth:`JointStateCodec.decode`; the view's arrays hold 12 or 24 values."""
        try:
            (flen,) = _U32.unpack_from(data, 12)
            (count,) = _U32.unpack_from(data, 16 + flen + (-flen) % 4)
        except struct.error as err:
            msg = f'not a serialized JointState: {err}'
            raise CdrError(msg) from err
        codec = self.drive if count == self.drive.n else self.torque
        try:
            return codec.decode(data, size)
        except CdrError as err:
            if 'does not carry' not in str(err):  # not a JointState at all
                raise
            text = (f'JointState does not carry the {self.n} joints {self.names[0]}..'
                    f'{self.names[-1]} (torque only) or those and their {self.n} '
                    f'"<joint>/gains" (a drive command) with all three arrays filled')
            raise CdrError(text) from err


CODECS: dict[str, JointStateCodec | CommandCodec] = {
    T.JOINT_STATES: JointStateCodec(T.JOINT_NAMES),
    T.FOOT_FORCES: JointStateCodec(T.FOOT_NAMES),
    T.HIP_STATES: JointStateCodec(T.HIP_NAMES),
    T.REFERENCE: JointStateCodec(T.REFERENCE_NAMES),
    T.JOINT_COMMANDS: CommandCodec(T.JOINT_NAMES, T.DRIVE_COMMAND_NAMES),
}
"""One codec per JointState topic of the contract."""
