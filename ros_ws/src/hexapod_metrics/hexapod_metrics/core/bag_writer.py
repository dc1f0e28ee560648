"""Write rosbag2 (Jazzy, metadata version 9) bags: ``metadata.yaml`` plus one MCAP file.

Layout and crash safety:

* MCAP profile ``ros2``, schemas ``ros2msg`` with rosbag2's full definition text, channels
  ``cdr`` with ``offered_qos_profiles`` and ``topic_type_hash`` metadata, like rosbag2's
  MCAP storage plugin. Schema and Channel records go to the data section as soon as a topic
  is added; messages go into chunks (one stream in arrival order, uncompressed by default
  like rosbag2's MCAP plugin) followed by their Message Index records; Chunk Indexes,
  Statistics and a ``rosbag2`` Metadata record go into the summary written at close.
* The file always ends with a Data End record, a Footer without summary and the magic:
  every chunk is written over the previous tail together with a new one. A writer killed
  with SIGKILL therefore leaves a file that MCAP readers (``mcap``, ``rosbags``) read as an
  unindexed file with every flushed chunk. A chunk is flushed when it reaches
  ``chunk_size`` bytes or when it is older than ``flush_interval_s``.
* ``metadata.yaml`` is written at :meth:`BagWriter.open`, when a topic is added, at most
  every ``metadata_interval_s`` at a chunk flush, and at close; always to a temporary
  file renamed over the old one, so it is never half written. Its counts cover the
  messages flushed so far.
"""

from __future__ import annotations

import json
import os
import re
import struct
import threading
import time
import zlib
from array import array
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from . import cdr
from .errors import BagWriteError
from .msgdefs import TYPE_CLOCK, TYPE_DIAGNOSTIC_ARRAY, TYPE_JOINT_STATE, TYPE_STRING, lookup

__all__ = ['QOS_PRESETS', 'BagWriter', 'QosProfile', 'qos_yaml']

MAGIC = b'\x89MCAP0\r\n'
LIBRARY = 'hexapod_metrics bag_writer 1'
ROS_DISTRO = 'jazzy'
_INFINITE = (9223372036, 854775807)  # RMW_DURATION_INFINITE as rosbag2 writes it
_NO_START = 2**63 - 1  # rosbag2's starting_time of a bag without messages


@dataclass(frozen=True)
class QosProfile:
    """One offered QoS profile, spelled as rosbag2 Jazzy writes it (version 9 enums)."""

    reliability: str = 'reliable'
    durability: str = 'volatile'
    history: str = 'unknown'
    depth: int = 0
    deadline: tuple[int, int] = _INFINITE
    lifespan: tuple[int, int] = _INFINITE
    liveliness: str = 'automatic'
    liveliness_lease_duration: tuple[int, int] = _INFINITE
    avoid_ros_namespace_conventions: bool = False

    def lines(self) -> list[str]:
        """yaml-cpp block lines of this profile as one sequence item."""
        out = [f'- history: {self.history}', f'  depth: {self.depth}']
        out += [f'  reliability: {self.reliability}', f'  durability: {self.durability}']
        for key, (sec, nsec) in (('deadline', self.deadline), ('lifespan', self.lifespan)):
            out += [f'  {key}:', f'    sec: {sec}', f'    nsec: {nsec}']
        sec, nsec = self.liveliness_lease_duration
        out += [f'  liveliness: {self.liveliness}', '  liveliness_lease_duration:']
        out += [f'    sec: {sec}', f'    nsec: {nsec}']
        flag = 'true' if self.avoid_ros_namespace_conventions else 'false'
        out.append(f'  avoid_ros_namespace_conventions: {flag}')
        return out


QOS_PRESETS: dict[str, QosProfile] = {
    'reliable': QosProfile(),
    'transient_local': QosProfile(durability='transient_local'),
    'best_effort': QosProfile(reliability='best_effort'),
}
"""What a Jazzy recorder stores for publishers with these QoS (discovery reports no depth)."""


def qos_yaml(profiles: Sequence[QosProfile]) -> str:
    """The channel's ``offered_qos_profiles`` string: yaml-cpp's ``Dump`` of the list."""
    return '\n'.join(line for p in profiles for line in p.lines())


# --------------------------------------------------------------------------- MCAP records

_U16 = struct.Struct('<H')
_U32 = struct.Struct('<I')
_U64 = struct.Struct('<Q')
_MSG_HEADER = struct.Struct('<BQHIQQ')  # opcode, length, channel, sequence, log, publish
_TAIL = (
    b'\x0f' + _U64.pack(4) + _U32.pack(0)  # Data End, no data CRC
    + b'\x02' + _U64.pack(20) + _U64.pack(0) + _U64.pack(0) + _U32.pack(0)  # Footer
    + MAGIC
)


def _string(text: str) -> bytes:
    raw = text.encode()
    return _U32.pack(len(raw)) + raw


def _record(opcode: int, body: bytes) -> bytes:
    return bytes((opcode,)) + _U64.pack(len(body)) + body


def _string_map(items: Mapping[str, str]) -> bytes:
    body = b''.join(_string(k) + _string(v) for k, v in sorted(items.items()))
    return _U32.pack(len(body)) + body


def _compressor(name: str) -> Callable[[bytes], bytes]:
    if name == 'zstd':
        import zstandard

        compressor = zstandard.ZstdCompressor(level=1, write_checksum=True)
        return lambda data: bytes(compressor.compress(data))
    if name == 'lz4':
        import lz4.frame

        return lambda data: lz4.frame.compress(data, store_size=True)
    if name == '':
        return bytes
    msg = f"unknown compression {name!r}: use 'zstd', 'lz4' or ''"
    raise BagWriteError(msg)


# --------------------------------------------------------------------------- metadata.yaml

_PLAIN = re.compile(r'[A-Za-z_/.][A-Za-z0-9_/.\-]*')
_SPECIAL = {'true', 'false', 'yes', 'no', 'on', 'off', 'null', 'y', 'n', '~'}


def _scalar(text: str) -> str:
    """A YAML scalar the way yaml-cpp spells it for our values (plain when unambiguous)."""
    if _PLAIN.fullmatch(text) and text.lower() not in _SPECIAL:
        return text
    return json.dumps(text)


@dataclass
class _Topic:
    name: str
    msgtype: str
    channel_id: int
    qos: tuple[QosProfile, ...]
    type_hash: str
    sequence: int = 0


class _Commit(NamedTuple):
    """What one write to the file added; appending it to the log is the commit."""

    end: int
    """End of the data section after this write."""
    chunk_index: bytes = b''
    counts: tuple[tuple[int, int], ...] = ()
    """(channel, messages) in the chunk written."""
    start_time: int = _NO_START
    end_time: int = 0


@dataclass
class _Chunk:
    """The chunk being filled: raw records and per-channel (log time, offset) pairs."""

    data: bytearray = field(default_factory=bytearray)
    index: dict[int, array[int]] = field(default_factory=dict)
    start: int = _NO_START
    end: int = 0
    opened: float = 0.0


class BagWriter:
    """Write one rosbag2 bag directory; cheap constructor, I/O in :meth:`open`/:meth:`close`.

    ``compression`` is the chunk compression: ``''`` (default: decoding is then bound by
    memory bandwidth, about twice as fast as with zstd or lz4, see
    ``scripts/bench_bag_decode.py``), ``'zstd'`` (level 1, about half the size) or ``'lz4'``;
    ``chunk_size`` bounds the uncompressed chunk (and what a SIGKILL can lose), as does
    ``flush_interval_s`` in time. ``custom_data`` goes to ``metadata.yaml``.
    Thread-safe; :meth:`close` may be called from a signal handler, even one that
    interrupts :meth:`write` (the close then happens when that write returns).
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        compression: str = '',
        chunk_size: int = 1 << 20,
        flush_interval_s: float = 1.0,
        metadata_interval_s: float = 1.0,
        custom_data: Mapping[str, str] | None = None,
    ) -> None:
        """Remember the settings; nothing touches the disk before :meth:`open`."""
        self.path = Path(path)
        self.mcap_path = self.path / f'{self.path.name}_0.mcap'
        self._compression = compression
        self._compress = _compressor(compression)
        self._chunk_size = int(chunk_size)
        self._flush_interval = float(flush_interval_s)
        self._metadata_interval = float(metadata_interval_s)
        self._custom = dict(custom_data or {})
        self._lock = threading.RLock()
        self._busy: int | None = None  # id of the thread inside write()/flush()
        self._closing = False
        self._close_requested = False
        self._fd: int | None = None
        self._closed = False
        self._log: list[_Commit] = [_Commit(0)]  # one entry per completed write
        self._topics: dict[str, _Topic] = {}
        self._schemas: dict[str, tuple[int, bytes]] = {}
        self._summary_schemas: list[bytes] = []
        self._summary_channels: list[bytes] = []
        self._metadata_indexes: list[bytes] = []  # Metadata Index records of add_metadata
        self._chunk = _Chunk()
        self._last_metadata = 0.0

    # ------------------------------------------------------------------ lifecycle

    def open(self) -> BagWriter:
        """Create the bag directory, the MCAP file and a first ``metadata.yaml``."""
        with self._lock:
            if self._fd is not None or self._closed:
                msg = f'bag writer for {self.path} was already opened'
                raise BagWriteError(msg)
            try:
                if self.path.exists() and (not self.path.is_dir() or any(self.path.iterdir())):
                    msg = f'bag path {self.path} already exists and is not an empty directory'
                    raise BagWriteError(msg)
                self.path.mkdir(parents=True, exist_ok=True)
                fd = os.open(self.mcap_path, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o644)
            except OSError as err:
                msg = f'cannot create bag {self.path}: {err.strerror}'
                raise BagWriteError(msg) from err
            self._fd = fd
            header = MAGIC + _record(0x01, _string('ros2') + _string(LIBRARY))
            self._pwrite(header + _TAIL, 0)
            self._log.append(_Commit(len(header)))
            self._write_metadata()
        return self

    def close(self) -> None:
        """Flush, write the summary and the final ``metadata.yaml``; idempotent."""
        if self._busy == threading.get_ident():  # a signal handler interrupted write()
            self._close_requested = True
            return
        with self._lock:
            self._close_locked()

    def __enter__(self) -> BagWriter:
        """Open on entering ``with``."""
        return self.open()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        """Close on leaving ``with``, also after an exception."""
        self.close()

    @property
    def closed(self) -> bool:
        """True once :meth:`close` completed."""
        return self._closed

    @property
    def message_count(self) -> int:
        """Messages written so far (flushed or not)."""
        pending = sum(len(pairs) // 2 for pairs in self._chunk.index.values())
        return sum(self._flushed_counts().values()) + pending

    # ------------------------------------------------------------------ topics and messages

    def add_topic(
        self,
        name: str,
        msgtype: str,
        qos: str | QosProfile | Sequence[QosProfile] = 'reliable',
        *,
        definition: str | None = None,
        type_hash: str = '',
    ) -> None:
        """Declare a topic; known types carry their definition, others need ``definition``."""
        with self._lock:
            self._check_open()
            known = lookup(msgtype)
            if known is not None:
                msgtype = known.name
            if name in self._topics:
                if self._topics[name].msgtype != msgtype:
                    msg = f'topic {name} already has type {self._topics[name].msgtype}'
                    raise BagWriteError(msg)
                return
            if definition is None:
                if known is None:
                    msg = f'unknown message type {msgtype!r}: pass definition= (ros2msg text)'
                    raise BagWriteError(msg)
                definition, type_hash = known.definition, type_hash or known.type_hash
            profiles = self._profiles(qos)
            schema_id, schema = self._schemas.get(msgtype, (len(self._schemas) + 1, b''))
            new_schema = not schema
            if new_schema:
                body = _U16.pack(schema_id) + _string(msgtype) + _string('ros2msg')
                schema = _record(0x03, body + _string(definition))
            channel_id = len(self._topics) + 1
            meta = {'offered_qos_profiles': qos_yaml(profiles), 'topic_type_hash': type_hash}
            channel = _record(
                0x04,
                _U16.pack(channel_id) + _U16.pack(schema_id) + _string(name)
                + _string('cdr') + _string_map(meta),
            )
            self._append((schema if new_schema else b'') + channel)
            if new_schema:
                self._schemas[msgtype] = (schema_id, schema)
                self._summary_schemas.append(schema)
            self._summary_channels.append(channel)
            self._topics[name] = _Topic(name, msgtype, channel_id, profiles, type_hash)
            self._write_metadata()

    def add_metadata(self, name: str, items: Mapping[str, str]) -> None:
        """Write an MCAP Metadata record now (data section) and index it in the summary.

        It is on disk when this returns, so a writer killed later still leaves it to
        readers that scan the file.
        """
        with self._lock:
            self._check_open()
            at = self._end
            record = _record(0x0C, _string(name) + _string_map(items))
            self._append(record)
            self._metadata_indexes.append(_record(
                0x0D, _U64.pack(at) + _U64.pack(len(record)) + _string(name)))

    def set_custom_data(self, key: str, value: str) -> None:
        """Set one ``custom_data`` entry of ``metadata.yaml`` and rewrite it now."""
        with self._lock:
            self._custom[key] = value
            if self._fd is not None:
                self._write_metadata()

    def write(self, topic: str, timestamp_ns: int, data: bytes | bytearray | memoryview) -> None:
        """Append one serialized (CDR) message received at ``timestamp_ns`` (log time)."""
        with self._lock:
            self._busy = threading.get_ident()
            try:
                self._write_locked(topic, int(timestamp_ns), data)
            finally:
                self._busy = None
                if self._close_requested:
                    self._close_locked()

    def write_joint_state(
        self,
        topic: str,
        stamp_ns: int,
        names: Sequence[str],
        position: Sequence[float] | npt.NDArray[np.float64],
        velocity: Sequence[float] | npt.NDArray[np.float64],
        effort: Sequence[float] | npt.NDArray[np.float64],
        *,
        frame_id: str = '',
        log_time_ns: int | None = None,
    ) -> None:
        """Serialize and write a JointState; all three arrays must have one value per name."""
        sizes = (len(position), len(velocity), len(effort))
        if sizes != (len(names),) * 3:
            msg = (
                f'{topic}: position/velocity/effort have {sizes} values for {len(names)} names;'
                ' fill all three arrays (an empty one breaks rosbags)'
            )
            raise BagWriteError(msg)
        data = cdr.encode_joint_state(stamp_ns, names, position, velocity, effort, frame_id)
        self._write_typed(topic, TYPE_JOINT_STATE, stamp_ns, log_time_ns, data)

    def write_string(self, topic: str, log_time_ns: int, text: str) -> None:
        """Write a ``std_msgs/msg/String`` (topics default to transient-local QoS)."""
        self._write_typed(topic, TYPE_STRING, log_time_ns, None, cdr.encode_string(text))

    def write_clock(self, topic: str, stamp_ns: int, log_time_ns: int | None = None) -> None:
        """Write a ``rosgraph_msgs/msg/Clock``."""
        self._write_typed(topic, TYPE_CLOCK, stamp_ns, log_time_ns, cdr.encode_clock(stamp_ns))

    def write_diagnostic_array(
        self,
        topic: str,
        stamp_ns: int,
        statuses: Sequence[cdr.DiagnosticStatus],
        *,
        log_time_ns: int | None = None,
    ) -> None:
        """Write a ``diagnostic_msgs/msg/DiagnosticArray``."""
        data = cdr.encode_diagnostic_array(stamp_ns, statuses)
        self._write_typed(topic, TYPE_DIAGNOSTIC_ARRAY, stamp_ns, log_time_ns, data)

    def flush(self) -> None:
        """Write the pending chunk now (it stays readable after a crash)."""
        with self._lock:
            self._check_open()
            self._busy = threading.get_ident()
            try:
                self._flush_chunk()
            finally:
                self._busy = None
                if self._close_requested:
                    self._close_locked()

    # ------------------------------------------------------------------ internals

    def _write_typed(
        self,
        topic: str,
        msgtype: str,
        stamp_ns: int,
        log_time_ns: int | None,
        data: bytes,
    ) -> None:
        with self._lock:
            if topic not in self._topics:
                qos = 'transient_local' if msgtype == TYPE_STRING else 'reliable'
                self.add_topic(topic, msgtype, qos)
            elif self._topics[topic].msgtype != msgtype:
                msg = f'topic {topic} has type {self._topics[topic].msgtype}, not {msgtype}'
                raise BagWriteError(msg)
            self.write(topic, stamp_ns if log_time_ns is None else log_time_ns, data)

    @staticmethod
    def _profiles(qos: str | QosProfile | Sequence[QosProfile]) -> tuple[QosProfile, ...]:
        if isinstance(qos, QosProfile):
            return (qos,)
        if isinstance(qos, str):
            if qos not in QOS_PRESETS:
                msg = f'unknown QoS preset {qos!r}; use one of {sorted(QOS_PRESETS)}'
                raise BagWriteError(msg)
            return (QOS_PRESETS[qos],)
        return tuple(qos)

    def _check_open(self) -> None:
        if self._fd is None:
            state = 'closed' if self._closed else 'not open'
            msg = f'bag writer for {self.path} is {state}; open() it or use "with BagWriter"'
            raise BagWriteError(msg)

    def _write_locked(
        self, topic: str, log_time: int, data: bytes | bytearray | memoryview,
    ) -> None:
        self._check_open()
        if log_time < 0:
            msg = f'{topic}: negative timestamp {log_time} ns cannot be stored'
            raise BagWriteError(msg)
        info = self._topics.get(topic)
        if info is None:
            msg = f'topic {topic} was not added; call add_topic({topic!r}, msgtype) first'
            raise BagWriteError(msg)
        chunk = self._chunk
        buf = chunk.data
        now = time.monotonic()
        if not buf:
            chunk.opened = now
        offsets = chunk.index.get(info.channel_id)
        if offsets is None:
            offsets = chunk.index[info.channel_id] = array('Q')
        record = _MSG_HEADER.pack(
            5, 22 + len(data), info.channel_id, info.sequence & 0xFFFFFFFF, log_time, log_time,
        ) + data
        start = len(buf)
        chunk.start = min(chunk.start, log_time)  # a wider range than needed is harmless
        chunk.end = max(chunk.end, log_time)
        # One C call each, which a Python signal handler cannot split: a handler that
        # raises leaves at worst a record without index entry (unread), never garbage.
        buf += record
        offsets.extend((log_time, start))
        info.sequence += 1
        if len(buf) >= self._chunk_size or now - chunk.opened >= self._flush_interval:
            self._flush_chunk()

    def _flush_chunk(self) -> None:
        chunk = self._chunk
        if not chunk.data:
            return
        raw = bytes(chunk.data)
        compressed = self._compress(raw)
        body = (
            _U64.pack(chunk.start) + _U64.pack(chunk.end) + _U64.pack(len(raw))
            + _U32.pack(zlib.crc32(raw)) + _string(self._compression)
            + _U64.pack(len(compressed)) + compressed
        )
        record = _record(0x06, body)
        chunk_start = self._end
        indexes = []
        offsets = []
        at = chunk_start + len(record)
        for channel_id, pairs in sorted(chunk.index.items()):
            body = _U16.pack(channel_id) + _U32.pack(8 * len(pairs)) + pairs.tobytes()
            rec = _record(0x07, body)
            offsets.append(_U16.pack(channel_id) + _U64.pack(at))
            indexes.append(rec)
            at += len(rec)
        index_bytes = b''.join(indexes)
        offset_map = b''.join(offsets)
        chunk_index = _record(
            0x08,
            _U64.pack(chunk.start) + _U64.pack(chunk.end) + _U64.pack(chunk_start)
            + _U64.pack(len(record)) + _U32.pack(len(offset_map)) + offset_map
            + _U64.pack(len(index_bytes)) + _string(self._compression)
            + _U64.pack(len(compressed)) + _U64.pack(len(raw)),
        )
        counts = tuple((c, len(pairs) // 2) for c, pairs in chunk.index.items())
        commit = _Commit(at, chunk_index, counts, chunk.start, chunk.end)
        self._chunk = _Chunk()
        try:
            self._append(record + index_bytes, commit)
        finally:
            if self._log[-1] is not commit:  # not committed: keep the chunk for later
                self._chunk = chunk
        first = sum(1 for c in self._log if c.chunk_index) == 1
        if first or time.monotonic() - self._last_metadata >= self._metadata_interval:
            self._write_metadata()

    @property
    def _end(self) -> int:
        """File offset where the data section ends and the tail starts."""
        return self._log[-1].end

    def _append(self, data: bytes, commit: _Commit | None = None) -> None:
        """Write ``data`` at the end of the data section, then a fresh tail; commit it.

        The commit is one list append: a signal handler that raises cannot leave the file
        and the bookkeeping disagreeing (an uncommitted write is overwritten by the next).
        """
        self._pwrite(data + _TAIL, self._end)
        self._log.append(commit or _Commit(self._end + len(data)))

    def _flushed_counts(self) -> dict[int, int]:
        counts: dict[int, int] = {}
        for commit in self._log:
            for channel, n in commit.counts:
                counts[channel] = counts.get(channel, 0) + n
        return counts

    def _flushed_times(self) -> tuple[int, int]:
        starts = [c.start_time for c in self._log if c.counts]
        ends = [c.end_time for c in self._log if c.counts]
        return (min(starts), max(ends)) if starts else (_NO_START, 0)

    def _pwrite(self, data: bytes, offset: int) -> None:
        assert self._fd is not None
        view = memoryview(data)
        try:
            while view:
                done = os.pwrite(self._fd, view, offset)
                view, offset = view[done:], offset + done
        except OSError as err:
            msg = f'cannot write bag file {self.mcap_path}: {err.strerror}'
            raise BagWriteError(msg) from err

    def _close_locked(self) -> None:
        self._close_requested = False
        if self._fd is None or self._closing:
            return
        self._closing = True
        try:
            self._flush_chunk()
            self._write_summary()
        finally:
            fd, self._fd = self._fd, None
            os.close(fd)
            self._closed = True
        self._write_metadata(final=True)

    def _write_summary(self) -> None:
        metadata_start = self._end
        metadata = _record(
            0x0C,
            _string('rosbag2') + _string_map({'serialized_metadata': self._metadata_text(0)}),
        )
        data_end = b'\x0f' + _U64.pack(4) + _U32.pack(0)
        summary_start = metadata_start + len(metadata) + len(data_end)
        groups: list[tuple[int, bytes]] = [
            (0x03, b''.join(self._summary_schemas)),
            (0x04, b''.join(self._summary_channels)),
            (0x08, b''.join(c.chunk_index for c in self._log)),
            (0x0D, b''.join(self._metadata_indexes) + _record(
                0x0D, _U64.pack(metadata_start) + _U64.pack(len(metadata))
                + _string('rosbag2'))),
            (0x0B, self._statistics()),
        ]
        summary = b''
        offsets = b''
        for opcode, group in groups:
            if group:
                offsets += _record(
                    0x0E,
                    bytes((opcode,)) + _U64.pack(summary_start + len(summary))
                    + _U64.pack(len(group)),
                )
                summary += group
        offset_start = summary_start + len(summary)
        footer = b'\x02' + _U64.pack(20) + _U64.pack(summary_start) + _U64.pack(offset_start)
        crc = zlib.crc32(summary + offsets + footer)
        tail = metadata + data_end + summary + offsets + footer + _U32.pack(crc) + MAGIC
        self._pwrite(tail, metadata_start)
        assert self._fd is not None
        os.ftruncate(self._fd, metadata_start + len(tail))

    def _statistics(self) -> bytes:
        flushed = self._flushed_counts()
        counts = b''.join(
            _U16.pack(t.channel_id) + _U64.pack(flushed.get(t.channel_id, 0))
            for t in self._topics.values()
        )
        total = sum(flushed.values())
        start, end = self._flushed_times() if total else (0, 0)
        chunks = sum(1 for c in self._log if c.chunk_index)
        return _record(
            0x0B,
            _U64.pack(total) + _U16.pack(len(self._schemas)) + _U32.pack(len(self._topics))
            + _U32.pack(0) + _U32.pack(1) + _U32.pack(chunks)
            + _U64.pack(start) + _U64.pack(end) + _U32.pack(len(counts)) + counts,
        )

    def _metadata_text(self, indent: int) -> str:
        """yaml-cpp style rosbag2 metadata (flushed messages only), keys at ``indent``."""
        flushed = self._flushed_counts()
        total = sum(flushed.values())
        start, end = self._flushed_times()
        duration = end - start if total else 0
        name = self.mcap_path.name
        lines = [
            'version: 9',
            'storage_identifier: mcap',
            'duration:',
            f'  nanoseconds: {duration}',
            'starting_time:',
            f'  nanoseconds_since_epoch: {start}',
            f'message_count: {total}',
        ]
        if self._topics:
            lines.append('topics_with_message_count:')
            for topic in self._topics.values():
                lines += [
                    '  - topic_metadata:',
                    f'      name: {_scalar(topic.name)}',
                    f'      type: {_scalar(topic.msgtype)}',
                    '      serialization_format: cdr',
                    '      offered_qos_profiles:',
                ]
                lines += ['        ' + line for p in topic.qos for line in p.lines()]
                lines += [
                    f'      type_description_hash: {_scalar(topic.type_hash)}',
                    f'    message_count: {flushed.get(topic.channel_id, 0)}',
                ]
        else:
            lines.append('topics_with_message_count: []')
        lines += [
            'compression_format: ""',
            'compression_mode: ""',
            'relative_file_paths:',
            f'  - {_scalar(name)}',
            'files:',
            f'  - path: {_scalar(name)}',
            '    starting_time:',
            f'      nanoseconds_since_epoch: {start}',
            '    duration:',
            f'      nanoseconds: {duration}',
            f'    message_count: {total}',
        ]
        if self._custom:
            lines.append('custom_data:')
            lines += [f'  {_scalar(k)}: {_scalar(v)}' for k, v in self._custom.items()]
        else:
            lines.append('custom_data: ~')
        lines.append(f'ros_distro: {ROS_DISTRO}')
        return '\n'.join(' ' * indent + line for line in lines)

    def _write_metadata(self, *, final: bool = False) -> None:
        """Atomically replace ``metadata.yaml`` (tmp file + rename)."""
        text = 'rosbag2_bagfile_information:\n' + self._metadata_text(2)
        target = self.path / 'metadata.yaml'
        tmp = self.path / '.metadata.yaml.tmp'
        try:
            with open(tmp, 'w', encoding='utf-8') as fh:
                fh.write(text)
                if final:
                    fh.flush()
                    os.fsync(fh.fileno())
            os.replace(tmp, target)
        except OSError as err:
            msg = f'cannot write {target}: {err.strerror}'
            raise BagWriteError(msg) from err
        self._last_metadata = time.monotonic()
