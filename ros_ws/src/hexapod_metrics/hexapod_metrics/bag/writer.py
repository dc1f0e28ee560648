"""Write rosbag2 (Jazzy, metadata version 9) bags: ``metadata.yaml`` plus MCAP files.

Layout:

* MCAP profile ``ros2``, schemas ``ros2msg`` with rosbag2's full definition text, channels
  ``cdr`` with ``offered_qos_profiles`` and ``topic_type_hash`` metadata, like rosbag2's
  MCAP storage plugin. Schema and Channel records go to the data section when a topic is
  added; messages go into chunks (uncompressed by default, like rosbag2's MCAP plugin),
  each followed by its Message Index records.
* Order: messages wait in a reorder buffer and each chunk takes those older than a
  watermark, sorted by (log time, channel). With ``sync_topics`` (the topics published at
  every tick) the watermark is the oldest "newest log time" among them (and
  among the ``follow_topics`` seen so far: slower, optional publishers), less
  ``reorder_window_ns``: every chunk covers the same log-time span for every tick topic,
  and chunks follow each other in log-time order. A tick topic more than ``max_lag_ns``
  behind the others (a dead publisher) stops holding the watermark; one never seen holds
  it for ``unseen_wait_s`` (wall s) after the first tick-topic message. A message older than
  the last watermark still goes into the next chunk and is counted in
  :attr:`BagWriter.late_messages` (the summary indexes it, so indexed readers still order).

Crash safety:

* After every write the file ends with a complete tail: Metadata records (``rosbag2``,
  ``hexapod_writer`` with the writer's state, and those added with
  :meth:`BagWriter.add_metadata`), Attachments, Data End, a summary (schemas, channels,
  chunk indexes, attachment and metadata indexes, statistics), the summary offsets, the
  footer and the magic. The next chunk is written over that tail together with a new one,
  in one ``pwrite``. A writer killed with SIGKILL therefore leaves an indexed file that
  seeking readers (``mcap``, ``rosbags``) open with every chunk flushed; its
  ``hexapod_writer`` record says ``state: open``, so this project's reader reports it as
  truncated. Only a kill inside that one ``pwrite`` leaves an unfinished tail, which this
  project's reader scans and the others refuse (the window is one write of up to a chunk:
  under a millisecond idle, longer for a writer starved of CPU).
* ``metadata.yaml`` is replaced (temporary file + rename, never half written) at open,
  when a topic is added, after every chunk and at close: it lags the MCAP by at most the
  chunk being written.
* A failed write (disk full, quota, I/O error) is an event, not a crash: the writer deletes
  its space reserve (``reserve_bytes``, a file in the bag directory held since open), puts
  the last complete tail back (marked ``state: failed`` with the reason), writes
  ``metadata.yaml``, closes, and raises :class:`~.errors.BagStorageError`; the bag then
  holds everything up to the last chunk written and opens in every reader.
* Split: with ``max_file_size`` (bytes) or ``max_file_duration_ns`` (log time) a new MCAP
  file ``<name>_<i>.mcap`` starts when the current one reaches the limit (like rosbag2's
  ``-b``/``-d``); each file is a complete MCAP with its own schemas, channels and summary.
"""

from __future__ import annotations

import json
import os
import re
import struct
import threading
import time
from bisect import bisect_left
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from operator import itemgetter
from pathlib import Path
from typing import NamedTuple, Self

import numpy as np
import numpy.typing as npt
from hexapod_common.core import cdr
from isal.isal_zlib import crc32  # zlib's CRC-32, about 4x faster (ISA-L)
from mcap.data_stream import RecordBuilder
from mcap.records import (
    Attachment,
    AttachmentIndex,
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    McapRecord,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)
from mcap.writer import MCAP0_MAGIC

from ._closing import Closing
from .errors import BagStorageError, BagWriteError
from .msgdefs import TYPE_CLOCK, TYPE_DIAGNOSTIC_ARRAY, TYPE_JOINT_STATE, TYPE_STRING, lookup

__all__ = ['QOS_PRESETS', 'RESERVE_NAME', 'BagWriter', 'QosProfile', 'qos_yaml']

MAGIC = MCAP0_MAGIC
LIBRARY = 'hexapod_metrics bag_writer 1'
ROS_DISTRO = 'jazzy'
_INFINITE = (9223372036, 854775807)  # RMW_DURATION_INFINITE as rosbag2 writes it
_NO_START = 2**63 - 1  # rosbag2's starting_time of a bag without messages
RESERVE_NAME = '.hexapod_reserve'
"""Disk space held in the bag directory while it is written (freed to close on a full disk)."""


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
_MSG_INDEX = struct.Struct('<BQHI')  # opcode, length, channel, length of the pairs


def _encode(*records: McapRecord) -> bytes:
    """MCAP records, serialized by the ``mcap`` library."""
    builder = RecordBuilder()
    for record in records:
        record.write(builder)
    return bytes(builder.end())  # type: ignore[no-untyped-call]  # mcap 1.6: unannotated


def _sorted(items: Mapping[str, str]) -> dict[str, str]:
    """A string map in key order (the library writes maps in insertion order)."""
    return dict(sorted(items.items()))


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


_Pending = tuple[int, int, bytes]
"""(log time, channel id, Message record) waiting in the reorder buffer."""
_ORDER = itemgetter(0, 1)
_TIME = itemgetter(0)


class _Commit(NamedTuple):
    """What one write to the file added; appending it to the file's log is the commit."""

    end: int
    """End of the data section after this write."""
    pending: list[_Pending]
    """The reorder buffer after this write (shared with later commits that flush nothing)."""
    chunk_index: bytes = b''
    counts: tuple[tuple[int, int], ...] = ()
    """(channel, messages) in the chunk written."""
    start_time: int = _NO_START
    end_time: int = 0
    tail: bytes = b''
    """The tail written after the data section."""


@dataclass
class _File:
    """One MCAP file of the bag: its last committed write and running totals of the others.

    Memory stays bounded by the summary (one Chunk Index per chunk): the tail and the reorder
    buffer of a commit are dropped once the next one lands (keeping every commit's tail and
    buffer once made a recorder grow by twice the bag's rate, quadratically in chunks)."""

    path: Path
    fd: int
    last: _Commit
    """The last committed write (its ``tail`` is the one on disk)."""
    size: int = 0
    """Bytes in the file (the committed data section and its tail)."""
    metadata_indexes: list[bytes] = field(default_factory=list)
    """Metadata Index records of the Metadata records in this file's data section."""
    chunk_indexes: bytearray = field(default_factory=bytearray)
    """The Chunk Index records of every committed chunk, in order."""
    _counts: dict[int, int] = field(default_factory=dict)
    _start: int = _NO_START
    _end: int = 0
    _chunks: int = 0

    def commit(self, commit: _Commit) -> None:
        """Make ``commit`` the last write; fold its chunk into the totals (one assignment
        at the end, so a signal handler that raises leaves the previous commit in place)."""
        if commit.chunk_index:
            self.chunk_indexes += commit.chunk_index
            self._chunks += 1
        for channel, n in commit.counts:
            self._counts[channel] = self._counts.get(channel, 0) + n
        if commit.counts:
            self._start = min(self._start, commit.start_time)
            self._end = max(self._end, commit.end_time)
        self.last = commit

    @property
    def end(self) -> int:
        """File offset where the data section ends and the tail starts."""
        return self.last.end

    def counts(self) -> dict[int, int]:
        """Messages per channel in the flushed chunks."""
        return dict(self._counts)

    def times(self) -> tuple[int, int]:
        """(first, last) log time of the flushed chunks."""
        return (self._start, self._end) if self._counts else (_NO_START, 0)

    def chunks(self) -> int:
        """Chunks in the file."""
        return self._chunks


class BagWriter(Closing):
    """Write one rosbag2 bag directory; cheap constructor, I/O in :meth:`open`/:meth:`close`.

    ``compression``: ``''`` (default: decoding is then bound by memory bandwidth, about
    twice as fast as with zstd or lz4, see ``scripts/bench_bag_decode.py``), ``'zstd'``
    (level 1, about half the size) or ``'lz4'``. A chunk is written when the reorder buffer
    holds ``chunk_size`` bytes (default 1 MiB: a SIGKILL inside the one ``pwrite`` of a
    chunk and its tail tears the file for every reader but ours, and a bigger chunk makes
    that window longer; bigger chunks read faster) or every ``flush_interval_s`` (wall s);
    ``sync_topics``, ``reorder_window_ns`` and ``max_lag_ns`` set its watermark (module docstring).
    ``custom_data`` goes to ``metadata.yaml``; ``reserve_bytes`` of disk are held back for
    closing the bag when the disk fills up; ``max_file_size`` (bytes) and
    ``max_file_duration_ns`` split the bag into files (0: no limit).
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
        metadata_interval_s: float = 0.0,
        custom_data: Mapping[str, str] | None = None,
        sync_topics: Sequence[str] = (),
        follow_topics: Sequence[str] = (),
        reorder_window_ns: int = 0,
        max_lag_ns: int = 2_000_000_000,
        max_pending_bytes: int = 64 << 20,
        unseen_wait_s: float = 10.0,
        reserve_bytes: int = 1 << 20,
        max_file_size: int = 0,
        max_file_duration_ns: int = 0,
    ) -> None:
        """Remember the settings; nothing touches the disk before :meth:`open`."""
        self.path = Path(path)
        self._compression = compression
        self._compress = _compressor(compression)
        self._chunk_size = int(chunk_size)
        self._flush_interval = float(flush_interval_s)
        self._metadata_interval = float(metadata_interval_s)
        self._custom = dict(custom_data or {})
        self._sync_names = tuple(sync_topics)
        self._follow_names = tuple(follow_topics)
        self._window = int(reorder_window_ns)
        self._max_lag = int(max_lag_ns)
        self._max_pending = int(max_pending_bytes)
        self._reserve_size = int(reserve_bytes)
        self._max_file_size = int(max_file_size)
        self._max_file_duration = int(max_file_duration_ns)
        self._lock = threading.RLock()
        self._busy: int | None = None  # id of the thread inside write()/flush()
        self._closing = False
        self._close_requested = False
        self._closed = False
        self._file: _File | None = None
        self._done: list[_File] = []  # files finished (split) before the current one
        self._topics: dict[str, _Topic] = {}
        self._by_channel: dict[int, _Topic] = {}
        self._schemas: dict[str, tuple[int, bytes]] = {}
        self._channels: list[bytes] = []
        self._attachments: dict[str, tuple[str, bytes, int]] = {}
        self._sync: set[int] = set()
        self._follow: set[int] = set()
        self._watched: set[int] = set()
        self._latest: dict[int, int] = {}  # sync channel -> newest log time written
        self._first_time: int | None = None
        self._first_wall: float | None = None
        self._unseen_wait = float(unseen_wait_s)
        self._flushed_until = -1  # every chunk so far took the messages below this
        self._opened = 0.0  # wall time of the last flush (attempt)
        self._pending_bytes = 0
        self._next_size_flush = self._chunk_size  # try a chunk when the buffer holds this
        self._last_metadata = 0.0
        self._state = 'open'
        self.failure = ''
        """Why the writer stopped early (a failed write), or ''."""
        self.late_messages = 0
        """Messages that came in older than the watermark already written."""
        self.lost_messages = 0
        """Messages not in the bag because a write failed."""

    # ------------------------------------------------------------------ lifecycle

    @property
    def mcap_path(self) -> Path:
        """The MCAP file being written (the first one before :meth:`open`)."""
        return self._file.path if self._file else self._file_path(0)

    @property
    def mcap_paths(self) -> list[Path]:
        """Every MCAP file of the bag so far."""
        return [f.path for f in self._files()]

    def _file_path(self, index: int) -> Path:
        return self.path / f'{self.path.name}_{index}.mcap'

    def _files(self) -> list[_File]:
        return self._done + ([self._file] if self._file else [])

    def open(self) -> Self:
        """Create the bag directory, the first MCAP file, the reserve and ``metadata.yaml``."""
        with self._lock:
            if self._file is not None or self._closed:
                msg = f'bag writer for {self.path} was already opened'
                raise BagWriteError(msg)
            try:
                if self.path.exists() and (not self.path.is_dir() or any(self.path.iterdir())):
                    msg = f'bag path {self.path} already exists and is not an empty directory'
                    raise BagWriteError(msg)
                self.path.mkdir(parents=True, exist_ok=True)
                self._make_reserve()
            except OSError as err:
                msg = f'cannot create bag {self.path}: {err.strerror}'
                raise BagWriteError(msg) from err
            self._start_file(0)
            self._write_metadata()
        return self

    def close(self) -> None:
        """Flush, write the final summary and ``metadata.yaml``; idempotent."""
        if self._busy == threading.get_ident():  # a signal handler interrupted write()
            self._close_requested = True
            return
        with self._lock:
            self._close_locked()

    def __enter__(self) -> Self:
        """Open on entering ``with``."""
        return self.open()

    @property
    def closed(self) -> bool:
        """True once the bag is closed (by :meth:`close` or after a failed write)."""
        return self._closed

    @property
    def message_count(self) -> int:
        """Messages written so far (flushed or not)."""
        pending = len(self._file.last.pending) if self._file else 0
        return sum(self._flushed_counts().values()) + pending

    # ------------------------------------------------------------------ topics, records

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
                schema = _encode(Schema(id=schema_id, data=definition.encode(),
                                        encoding='ros2msg', name=msgtype))
            channel_id = len(self._topics) + 1
            meta = {'offered_qos_profiles': qos_yaml(profiles), 'topic_type_hash': type_hash}
            channel = _encode(Channel(id=channel_id, topic=name, message_encoding='cdr',
                                      metadata=_sorted(meta), schema_id=schema_id))
            if new_schema:
                self._schemas[msgtype] = (schema_id, schema)
            self._channels.append(channel)
            topic = _Topic(name, msgtype, channel_id, profiles, type_hash)
            self._topics[name] = topic
            self._by_channel[channel_id] = topic
            if name in self._sync_names:
                self._sync.add(channel_id)
            elif name in self._follow_names:
                self._follow.add(channel_id)
            self._watched = self._sync | self._follow
            self._append((schema if new_schema else b'') + channel)
            self._write_metadata()

    def add_metadata(self, name: str, items: Mapping[str, str]) -> None:
        """Write an MCAP Metadata record now (data section) and index it in the summary.

        It is on disk when this returns (with a summary that indexes it), so a writer
        killed later still leaves it; records of one name accumulate. The names
        ``rosbag2`` and ``hexapod_writer`` are the writer's own.
        """
        if name in ('rosbag2', 'hexapod_writer'):
            msg = f'metadata record name {name!r} is reserved by the bag writer'
            raise BagWriteError(msg)
        with self._lock:
            self._check_open()
            f = self._file
            assert f is not None
            at = f.end
            record = _encode(Metadata(name, _sorted(items)))
            index = _encode(MetadataIndex(at, len(record), name))
            f.metadata_indexes.append(index)  # in the summary of the tail written next
            try:
                self._append(record)
            except BaseException:
                if f.metadata_indexes and f.metadata_indexes[-1] is index:
                    f.metadata_indexes.pop()
                raise

    def set_custom_data(self, key: str, value: str) -> None:
        """Set one ``custom_data`` entry of ``metadata.yaml`` and rewrite it now."""
        with self._lock:
            self._custom[key] = value
            if self._file is not None:
                self._write_metadata()

    def add_attachment(self, name: str, data: bytes, media_type: str = 'application/json',
                       log_time_ns: int = 0) -> None:
        """Store (or replace) an MCAP Attachment (kept in every tail written from now on)."""
        with self._lock:
            self._check_open()
            self._attachments[name] = (media_type, bytes(data), int(log_time_ns))
            self._append(b'')

    # ------------------------------------------------------------------ messages

    def write(self, topic: str, timestamp_ns: int, data: bytes | bytearray | memoryview) -> None:
        """Append one serialized (CDR) message with log time ``timestamp_ns``."""
        with self._lock:
            self._busy = threading.get_ident()
            try:
                self._write_locked(topic, int(timestamp_ns), data)
            finally:
                self._done_writing()

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
        """Write every buffered message now, watermark or not (readable after a crash)."""
        with self._lock:
            self._check_open()
            self._busy = threading.get_ident()
            try:
                self._flush_chunk(everything=True)
            finally:
                self._done_writing()

    def _done_writing(self) -> None:
        """Leave write()/flush(); run a close() that a signal handler asked for meanwhile."""
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
        if self._file is None:
            state = 'closed' if self._closed else 'not open'
            if self.failure:
                state += f' ({self.failure})'
            msg = f'bag writer for {self.path} is {state}; open() it or use "with BagWriter"'
            raise BagWriteError(msg)

    def _write_locked(
        self, topic: str, log_time: int, data: bytes | bytearray | memoryview,
    ) -> None:
        if self._file is None and self.failure:
            self.lost_messages += 1
        self._check_open()
        assert self._file is not None
        if log_time < 0:
            msg = f'{topic}: negative timestamp {log_time} ns cannot be stored'
            raise BagWriteError(msg)
        info = self._topics.get(topic)
        if info is None:
            msg = f'topic {topic} was not added; call add_topic({topic!r}, msgtype) first'
            raise BagWriteError(msg)
        channel = info.channel_id
        record = _MSG_HEADER.pack(
            5, 22 + len(data), channel, info.sequence & 0xFFFFFFFF, log_time, log_time,
        ) + data
        pending = self._file.last.pending
        now = time.monotonic()
        if not pending:
            self._opened = now
        # One C call, which a Python signal handler cannot split: a handler that raises
        # leaves the message either in the buffer or not, never half of it.
        pending.append((log_time, channel, record))
        info.sequence += 1
        self._pending_bytes += len(record)
        if self._first_time is None:
            self._first_time = log_time
        if log_time < self._flushed_until:
            self.late_messages += 1
        if channel in self._watched and log_time > self._latest.get(channel, -1):
            if self._first_wall is None and channel in self._sync:
                self._first_wall = now  # the wait for unseen tick topics starts here
            self._latest[channel] = log_time
        if (self._pending_bytes >= self._next_size_flush
                or now - self._opened >= self._flush_interval):
            self._flush_chunk()

    def _watermark(self) -> int | None:
        """Chunks take the buffered messages below this log time (None: all of them)."""
        if not self._sync:
            return None
        latest = [self._latest[c] for c in (*self._sync, *self._follow) if c in self._latest]
        if not latest:
            return -1
        leader = max(latest)
        live = [t for t in latest if leader - t <= self._max_lag]
        cut = min(live) - self._window
        if (len(self._sync - self._latest.keys())
                and (self._first_wall is None
                     or time.monotonic() - self._first_wall < self._unseen_wait)):
            cut = -1  # a tick topic not seen yet: wait for it (a while) before the 1st chunk
        if self._pending_bytes > self._max_pending:  # never hold more than this
            cut = max(cut, leader - self._window)
        return cut

    def _flush_chunk(self, *, everything: bool = False) -> None:
        assert self._file is not None
        self._opened = time.monotonic()
        before = self._file.last.pending
        self._next_size_flush = self._pending_bytes + self._chunk_size
        if not before:
            return
        cut = None if everything else self._watermark()
        pending = sorted(before, key=_ORDER)
        n = len(pending) if cut is None else bisect_left(pending, cut, key=_TIME)
        if n == 0:
            return
        taken, rest = pending[:n], pending[n:]
        times, channels, records = zip(*taken)
        raw = b''.join(records)
        sizes = np.fromiter(map(len, records), np.uint64, n)
        where = np.zeros(n, np.uint64)
        np.cumsum(sizes[:-1], out=where[1:])
        stamps = np.fromiter(times, np.uint64, n)
        ids = np.fromiter(channels, np.uint16, n)
        index: dict[int, bytes] = {}
        counts_list = []
        for channel_id in np.unique(ids).tolist():
            sel = ids == channel_id
            pairs = np.empty((int(sel.sum()), 2), '<u8')
            pairs[:, 0], pairs[:, 1] = stamps[sel], where[sel]
            index[channel_id] = pairs.tobytes()
            counts_list.append((channel_id, len(pairs)))
        start, end = taken[0][0], taken[-1][0]
        compressed = self._compress(raw)
        record = _encode(Chunk(
            compression=self._compression, data=compressed, message_end_time=end,
            message_start_time=start, uncompressed_crc=crc32(raw), uncompressed_size=len(raw)))
        chunk_start = self._file.end
        indexes = []
        offsets: dict[int, int] = {}
        at = chunk_start + len(record)
        for channel_id, pairs_bytes in sorted(index.items()):
            # Message Index by hand: the (time, offset) pairs are one numpy buffer, where
            # the library's MessageIndex packs them one by one in Python
            rec = (_MSG_INDEX.pack(0x07, 6 + len(pairs_bytes), channel_id, len(pairs_bytes))
                   + pairs_bytes)
            offsets[channel_id] = at
            indexes.append(rec)
            at += len(rec)
        chunk_index = _encode(ChunkIndex(
            chunk_length=len(record), chunk_start_offset=chunk_start,
            compression=self._compression, compressed_size=len(compressed),
            message_end_time=end, message_index_length=sum(len(r) for r in indexes),
            message_index_offsets=offsets, message_start_time=start,
            uncompressed_size=len(raw)))
        commit = _Commit(at, rest, chunk_index, tuple(counts_list), start, end)
        self._append(record + b''.join(indexes), commit)
        self._pending_bytes -= len(raw)
        self._next_size_flush = self._pending_bytes + self._chunk_size
        self._flushed_until = max(self._flushed_until, end + 1 if cut is None else cut)
        if time.monotonic() - self._last_metadata >= self._metadata_interval:
            self._write_metadata()
        self._maybe_split()

    def _append(self, data: bytes, commit: _Commit | None = None) -> None:
        """Write ``data`` at the end of the data section and a fresh tail; commit it.

        The commit is one list append: a signal handler that raises cannot leave the file
        and the bookkeeping disagreeing (an uncommitted write is overwritten by the next).
        A failed write closes the bag at its last commit and raises BagStorageError.
        """
        f = self._file
        assert f is not None
        if commit is None:
            commit = _Commit(f.end + len(data), f.last.pending)
        tail = self._tail(f, commit, self._state)
        try:
            _pwrite(f, data + tail, f.end)
            if commit.end + len(tail) < f.size:
                os.ftruncate(f.fd, commit.end + len(tail))
        except OSError as err:
            self._fail(err)
        f.size = commit.end + len(tail)
        f.commit(commit._replace(tail=tail))

    def _fail(self, err: OSError) -> None:
        """A write failed: restore a complete tail, close, raise :class:`BagStorageError`."""
        f = self._file
        assert f is not None
        why = err.strerror or str(err)
        self.failure = f'cannot write {f.path.name}: {why}'
        self._state = 'failed'
        self._drop_reserve()
        self.lost_messages += len(f.last.pending)
        last = f.last
        commit = last._replace(chunk_index=b'', counts=(), pending=[])
        restored = False
        for tail in (self._tail(f, commit, 'failed'), last.tail):
            try:
                _pwrite(f, tail, commit.end)
                os.ftruncate(f.fd, commit.end + len(tail))
            except OSError:
                continue
            restored = True
            break
        f.commit(commit)
        self._file = None
        self._done.append(f)
        os.close(f.fd)
        self._closed = True
        done = 'closed at its last complete chunk' if restored else 'left unfinished'
        try:
            self._write_metadata(final=True)
        except BagWriteError:
            done += ' (metadata.yaml not updated)'
        msg = f'{self.failure}; bag {self.path} {done}; {self.lost_messages} messages lost'
        raise BagStorageError(msg, why) from err

    def _tail(self, f: _File, commit: _Commit, state: str) -> bytes:
        """Metadata, attachments, Data End, summary, summary offsets, footer and magic."""
        start = commit.end
        writer = {'state': state, 'library': LIBRARY, 'late_messages': str(self.late_messages)}
        if self.failure:
            writer['failure'] = self.failure
        text = self._metadata_text(0, commit)
        records = [('rosbag2', {'serialized_metadata': text}), ('hexapod_writer', writer)]
        data = bytearray()
        meta_index = []
        for name, items in records:
            rec = _encode(Metadata(name, _sorted(items)))
            meta_index.append(_encode(MetadataIndex(start + len(data), len(rec), name)))
            data += rec
        attach_index = []
        for name, (media_type, content, log_time) in self._attachments.items():
            rec = _encode(Attachment(log_time, log_time, name, media_type, content))
            attach_index.append(_encode(AttachmentIndex(
                offset=start + len(data), length=len(rec), log_time=log_time,
                create_time=log_time, data_size=len(content), name=name, media_type=media_type)))
            data += rec
        data_end = _encode(DataEnd(0))
        summary_start = start + len(data) + len(data_end)
        chunk_indexes = bytes(f.chunk_indexes) + commit.chunk_index
        groups: list[tuple[int, bytes]] = [
            (0x03, b''.join(s for _, s in self._schemas.values())),
            (0x04, b''.join(self._channels)),
            (0x08, chunk_indexes),
            (0x0A, b''.join(attach_index)),
            (0x0D, b''.join(f.metadata_indexes) + b''.join(meta_index)),
            (0x0B, self._statistics(f, commit)),
        ]
        summary = bytearray()
        offsets = bytearray()
        for opcode, group in groups:
            if group:
                offsets += _encode(SummaryOffset(opcode, summary_start + len(summary),
                                                 len(group)))
                summary += group
        offset_start = summary_start + len(summary)
        footer = _encode(Footer(summary_start, offset_start, 0))[:-4]  # the CRC covers this
        crc = crc32(bytes(summary + offsets) + footer)
        return b''.join((data, data_end, summary, offsets, footer, _U32.pack(crc), MAGIC))

    def _statistics(self, f: _File, commit: _Commit) -> bytes:
        flushed = f.counts()
        for channel, n in commit.counts:
            flushed[channel] = flushed.get(channel, 0) + n
        counts = {t.channel_id: flushed.get(t.channel_id, 0) for t in self._topics.values()}
        total = sum(flushed.values())
        start, end = f.times()
        if commit.counts:
            start, end = min(start, commit.start_time), max(end, commit.end_time)
        if not total:
            start = end = 0
        chunks = f.chunks() + (1 if commit.chunk_index else 0)
        return _encode(Statistics(
            attachment_count=len(self._attachments), channel_count=len(self._topics),
            channel_message_counts=counts, chunk_count=chunks, message_count=total,
            message_end_time=end, message_start_time=start,
            metadata_count=2 + len(f.metadata_indexes), schema_count=len(self._schemas)))

    def _start_file(self, index: int) -> None:
        """Open MCAP file ``index`` with its header, schemas and channels."""
        path = self._file_path(index)
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o644)
        except OSError as err:
            msg = f'cannot create bag file {path}: {err.strerror}'
            raise BagWriteError(msg) from err
        pending = self._file.last.pending if self._file else []
        header = MAGIC + _encode(Header('ros2', LIBRARY))
        self._file = _File(path, fd, _Commit(len(header), pending))
        try:
            _pwrite(self._file, header, 0)
        except OSError as err:
            self._fail(err)
        self._append(b''.join(s for _, s in self._schemas.values()) + b''.join(self._channels))

    def _maybe_split(self) -> None:
        f = self._file
        assert f is not None
        start, end = f.times()
        big = self._max_file_size and f.size >= self._max_file_size
        long = self._max_file_duration and end - start >= self._max_file_duration
        if not (big or long):
            return
        self._finish_file(f, 'split')
        self._done.append(f)
        self._start_file(len(self._done))
        self._write_metadata()

    def _finish_file(self, f: _File, state: str) -> None:
        """Rewrite the tail of a finished file with its final state and close it."""
        commit = f.last
        tail = self._tail(f, commit._replace(chunk_index=b'', counts=()), state)
        try:
            _pwrite(f, tail, commit.end)
            os.ftruncate(f.fd, commit.end + len(tail))
        except OSError as err:
            self._fail(err)
        f.commit(commit._replace(chunk_index=b'', counts=(), tail=tail))
        os.close(f.fd)

    def _flushed_counts(self) -> dict[int, int]:
        counts: dict[int, int] = {}
        for f in self._files():
            for channel, n in f.counts().items():
                counts[channel] = counts.get(channel, 0) + n
        return counts

    def _flushed_times(self) -> tuple[int, int]:
        times = [f.times() for f in self._files()]
        starts = [s for s, _ in times if s != _NO_START]
        ends = [e for s, e in times if s != _NO_START]
        return (min(starts), max(ends)) if starts else (_NO_START, 0)

    def _make_reserve(self) -> None:
        if self._reserve_size <= 0:
            return
        fd = os.open(self._reserve_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        try:
            os.posix_fallocate(fd, 0, self._reserve_size)
        finally:
            os.close(fd)

    @property
    def _reserve_path(self) -> Path:
        return self.path / RESERVE_NAME

    def _drop_reserve(self) -> None:
        try:
            self._reserve_path.unlink()
        except OSError:
            pass

    def _close_locked(self) -> None:
        self._close_requested = False
        if self._file is None or self._closing:
            return
        self._closing = True
        self._drop_reserve()  # room for the last chunk and the summary on a full disk
        try:
            self._flush_chunk(everything=True)
            self._state = 'closed'
            f = self._file
            self._finish_file(f, 'closed')
            self._done.append(f)
            self._file = None
        finally:
            if self._file is not None:  # an exception before the file was finished
                os.close(self._file.fd)
                self._done.append(self._file)
                self._file = None
            self._closed = True
        self._write_metadata(final=True)

    def _file_stats(self, f: _File, extra: _Commit | None) -> tuple[dict[int, int], int, int]:
        """Messages per channel and (first, last) log time of ``f`` with ``extra`` added."""
        counts = f.counts()
        start, end = f.times()
        if extra is not None and extra.counts:
            for channel, n in extra.counts:
                counts[channel] = counts.get(channel, 0) + n
            start, end = min(start, extra.start_time), max(end, extra.end_time)
        return counts, start, end

    def _metadata_text(self, indent: int, extra: _Commit | None = None) -> str:
        """yaml-cpp style rosbag2 metadata (flushed messages only), keys at ``indent``.

        ``extra`` is a commit of the current file about to be written."""
        files = []
        flushed: dict[int, int] = {}
        for f in self._files():
            counts, start, end = self._file_stats(f, extra if f is self._file else None)
            files.append((f.path.name, sum(counts.values()), start, end))
            for channel, n in counts.items():
                flushed[channel] = flushed.get(channel, 0) + n
        if not files:
            files.append((self._file_path(0).name, 0, _NO_START, 0))
        total = sum(flushed.values())
        starts = [s for _, n, s, _ in files if n]
        start = min(starts) if starts else _NO_START
        end = max((e for _, n, _, e in files if n), default=0)
        duration = end - start if total else 0
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
        lines += ['compression_format: ""', 'compression_mode: ""', 'relative_file_paths:']
        lines += [f'  - {_scalar(name)}' for name, _, _, _ in files]
        lines.append('files:')
        for name, count, f_start, f_end in files:
            lines += [
                f'  - path: {_scalar(name)}',
                '    starting_time:',
                f'      nanoseconds_since_epoch: {f_start if count else _NO_START}',
                '    duration:',
                f'      nanoseconds: {f_end - f_start if count else 0}',
                f'    message_count: {count}',
            ]
        if self._custom:
            lines.append('custom_data:')
            lines += [f'  {_scalar(k)}: {_scalar(v)}' for k, v in self._custom.items()]
        else:
            lines.append('custom_data: ~')
        lines.append(f'ros_distro: {ROS_DISTRO}')
        return '\n'.join(' ' * indent + line for line in lines)

    def _write_metadata(self, *, final: bool = False) -> None:
        """Atomically replace ``metadata.yaml`` (tmp file + rename).

        Only the final write raises: before it, a failure (disk full) keeps the previous
        file, and the next MCAP write fails and closes the bag (:meth:`_fail`)."""
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
            try:
                tmp.unlink()
            except OSError:
                pass
            if final:
                msg = f'cannot write {target}: {err.strerror}'
                raise BagWriteError(msg) from err
            return
        self._last_metadata = time.monotonic()


def _pwrite(f: _File, data: bytes, offset: int) -> None:
    """Write all of ``data`` at ``offset`` of ``f`` (raises OSError)."""
    view = memoryview(data)
    while view:
        done = os.pwrite(f.fd, view, offset)
        view, offset = view[done:], offset + done
