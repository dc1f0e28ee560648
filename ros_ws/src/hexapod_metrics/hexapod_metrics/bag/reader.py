"""Read rosbag2 MCAP bags, complete or cut short, in bounded memory.

``open_bag`` accepts a bag directory (``metadata.yaml`` + ``*.mcap``) or one ``.mcap``
file. A file with a valid summary is indexed from it; any other file (writer killed,
bytes cut at any offset) is scanned record by record up to the first incomplete record,
and the bag reports ``truncated=True``. Messages are read one chunk at a time.

Every failure leaves the public functions as :class:`BagReadError` with a one-line
message; nothing else escapes and no loop can stall (each step consumes bytes).
"""

from __future__ import annotations

import os
import struct
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt
from hexapod_common.core import cdr
from hexapod_common.core.cdr import JointStateArrays, JointStateDecoder
from hexapod_common.core.errors import CdrError
from isal.isal_zlib import crc32  # zlib's CRC-32, about 4x faster (ISA-L)

from ._closing import Closing
from .errors import BagError, BagReadError
from .msgdefs import TYPE_JOINT_STATE

__all__ = [
    'Bag',
    'TopicInfo',
    'iter_joint_state_blocks',
    'open_bag',
    'read_joint_state_arrays',
    'read_joint_state_topics',
]

MAGIC = b'\x89MCAP0\r\n'
MAX_CHUNK = 1 << 30  # refuse to inflate a (corrupt) chunk claiming more than 1 GiB
_REC = struct.Struct('<BQ')
_MSG = struct.Struct('<HIQQ')
_U16 = struct.Struct('<H')
_U32 = struct.Struct('<I')
_U64 = struct.Struct('<Q')


#: Name of the metadata record that marks a copy made by ``reindex`` (source, reason).
REINDEXED = 'hexapod_reindexed'

class TopicInfo(NamedTuple):
    """One topic of a bag."""

    name: str
    msgtype: str
    message_count: int
    offered_qos_profiles: str
    type_hash: str


@contextmanager
def _boundary(what: str) -> Iterator[None]:
    """Translate any low-level failure into a one-line :class:`BagReadError`."""
    try:
        yield
    except BagError:
        raise
    except CdrError as err:
        msg = f'{what}: {err}'
        raise BagReadError(msg) from err
    except MemoryError as err:
        msg = f'{what}: out of memory (is the file corrupt?)'
        raise BagReadError(msg) from err
    except OSError as err:
        msg = f'{what}: {err.strerror or err}'
        raise BagReadError(msg) from err
    except Exception as err:
        text = str(err).splitlines()[0] if str(err) else type(err).__name__
        msg = f'{what}: damaged or not a bag ({text})'
        raise BagReadError(msg) from err


# --------------------------------------------------------------------------- MCAP parsing


class _Reader:
    """Little cursor over one record body."""

    def __init__(self, data: bytes, what: str) -> None:
        self.data, self.pos, self.what = data, 0, what

    def take(self, size: int) -> bytes:
        if size < 0 or self.pos + size > len(self.data):
            msg = f'{self.what}: record field runs past its record'
            raise BagReadError(msg)
        self.pos += size
        return self.data[self.pos - size:self.pos]

    def u16(self) -> int:
        return int(_U16.unpack(self.take(2))[0])

    def u32(self) -> int:
        return int(_U32.unpack(self.take(4))[0])

    def u64(self) -> int:
        return int(_U64.unpack(self.take(8))[0])

    def string(self) -> str:
        return self.take(self.u32()).decode(errors='replace')

    def string_map(self) -> dict[str, str]:
        end = self.u32() + self.pos
        out = {}
        while self.pos < end:
            key = self.string()
            out[key] = self.string()
        return out


@dataclass
class _Channel:
    id: int
    topic: str
    schema_id: int
    encoding: str
    metadata: dict[str, str]


@dataclass
class _Chunk:
    """A chunk record; ``indexes`` maps channel -> (offset, length) of its Message Index."""

    offset: int
    data_offset: int
    compressed_size: int
    uncompressed_size: int
    crc: int
    compression: str
    indexes: dict[int, tuple[int, int]] | None = field(default_factory=dict)


@dataclass
class _Loose:
    """A Message record outside any chunk."""

    offset: int
    length: int


class _McapFile:
    """Structure of one MCAP file: schemas, channels, chunks, counts, truncation."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.what = str(path)
        self.fd = os.open(path, os.O_RDONLY)
        self.size = os.fstat(self.fd).st_size
        self.schemas: dict[int, str] = {}
        self.channels: dict[int, _Channel] = {}
        self.blocks: list[_Chunk | _Loose] = []
        self.counts: dict[int, int] = {}
        self.truncated = False
        self.reason = ''
        self.data_start = 0
        self.summary_damaged = False
        self.metadata_index: dict[str, tuple[int, int]] = {}  # name -> the last record's
        self.metadata_at: list[tuple[int, int]] = []  # (offset, length) of Metadata records
        self.writer: dict[str, str] = {}
        """The ``hexapod_writer`` metadata record (state, late messages, failure), if any."""
        try:
            self._open()
        except BaseException:
            os.close(self.fd)
            raise

    # ------------------------------------------------------------------ structure

    def _read(self, offset: int, size: int) -> bytes:
        """Read exactly ``size`` bytes at ``offset`` (positional: safe across threads)."""
        data = os.pread(self.fd, size, offset)
        if len(data) != size:
            msg = f'{self.what}: file ends at {self.size} bytes, inside a record at {offset}'
            raise BagReadError(msg)
        return data

    def _open(self) -> None:
        if self.size == 0:
            msg = f'{self.what}: empty file, not an MCAP bag'
            raise BagReadError(msg)
        if self._read(0, min(8, self.size)) != MAGIC:
            msg = f'{self.what}: not an MCAP file (bad magic bytes)'
            raise BagReadError(msg)
        if self.size < 17:
            msg = f'{self.what}: MCAP file cut off before its header record'
            raise BagReadError(msg)
        opcode, length = _REC.unpack(self._read(8, 9))
        if opcode != 0x01 or 17 + length > self.size:
            msg = f'{self.what}: MCAP header record missing or cut off'
            raise BagReadError(msg)
        self.data_start = 17 + length
        if not self._read_summary():
            self._scan()

    def _read_summary(self) -> bool:
        """Index from the summary; False if there is none or it is unusable."""
        if self.size < self.data_start + 37:
            return False
        tail = self._read(self.size - 37, 37)
        if tail[-8:] != MAGIC or tail[:9] != b'\x02' + _U64.pack(20):
            return False
        summary_start, offsets_start, crc = struct.unpack('<QQI', tail[9:29])
        if not summary_start:
            return False
        end = offsets_start or self.size - 37
        if not self.data_start <= summary_start <= end <= self.size - 37:
            return False
        self.summary_damaged = True  # until parsed: there is a summary, is it usable?
        if crc:
            body = self._read(summary_start, self.size - 37 - summary_start) + tail[:25]
            if crc32(body) != crc:
                return False
        try:
            self._parse_summary(self._read(summary_start, end - summary_start))
        except BagReadError:
            self.schemas.clear()
            self.channels.clear()
            self.blocks.clear()
            self.counts.clear()
            self.metadata_index.clear()
            self.metadata_at.clear()
            return False
        self.summary_damaged = False
        try:
            self._writer_state()
        except BagReadError:
            self.writer = {}
        return True

    def _indexed_metadata(self, name: str) -> dict[str, str] | None:
        """The string map of the last Metadata record ``name`` the summary indexes."""
        where = self.metadata_index.get(name)
        if where is None:
            return None
        offset, length = where
        rd = _Reader(self._read(offset + 9, length - 9) if length > 9 else b'', self.what)
        rd.string()
        return rd.string_map()

    def _writer_state(self) -> None:
        """A summary written by a writer that did not close says so (killed, disk full),
        and a copy made by :func:`~.reindex.reindex` that its source was cut short."""
        info = self._indexed_metadata('hexapod_writer')
        if info is None:
            return
        self.writer = info
        state = info.get('state', 'closed')
        if state == 'open':
            self.truncated = True
            self.reason = ('the bag was not closed: its writer stopped (killed?) after its last'
                           ' chunk')
        elif state == 'failed':
            self.truncated = True
            self.reason = f'the writer stopped early: {info.get("failure", "write failed")}'
        made = self._indexed_metadata(REINDEXED)
        if made is not None:
            self.truncated = True
            self.reason = (f'reindexed from {made.get("source", "?")}, which was cut short: '
                           f'{made.get("reason", "?")}')

    def _parse_summary(self, data: bytes) -> None:
        pos = 0
        stats: dict[int, int] | None = None
        while pos + 9 <= len(data):
            opcode, length = _REC.unpack_from(data, pos)
            body = data[pos + 9:pos + 9 + length]
            if len(body) != length:
                msg = f'{self.what}: summary record runs past the summary'
                raise BagReadError(msg)
            pos += 9 + length
            if opcode == 0x03:
                self._schema(body)
            elif opcode == 0x04:
                self._channel(body)
            elif opcode == 0x08:
                self.blocks.append(self._chunk_index(body))
            elif opcode == 0x0D:
                rd = _Reader(body, self.what)
                offset, size = rd.u64(), rd.u64()
                if offset + size > self.size:
                    msg = f'{self.what}: metadata index points past the end of the file'
                    raise BagReadError(msg)
                self.metadata_index[rd.string()] = (offset, size)
                self.metadata_at.append((offset, size))
            elif opcode == 0x0B:
                rd = _Reader(body, self.what)
                rd.take(42)
                end = rd.u32() + rd.pos
                stats = {}
                while rd.pos < end:
                    channel = rd.u16()
                    stats[channel] = rd.u64()
        if stats is not None and (self.blocks or not sum(stats.values())):
            self.counts = stats
        elif self.blocks:
            self._count_from_indexes()
        else:  # messages without chunk indexes: only a scan finds them
            msg = f'{self.what}: summary without chunk indexes'
            raise BagReadError(msg)

    def _chunk_index(self, body: bytes) -> _Chunk:
        rd = _Reader(body, self.what)
        rd.u64()
        rd.u64()
        offset, length = rd.u64(), rd.u64()
        end = rd.u32() + rd.pos
        positions = {}
        while rd.pos < end:
            channel = rd.u16()
            positions[channel] = rd.u64()
        rd.u64()
        compression = rd.string()
        compressed, uncompressed = rd.u64(), rd.u64()
        if offset + 9 + length > self.size:
            msg = f'{self.what}: chunk index points past the end of the file'
            raise BagReadError(msg)
        head = self._read(offset, 9 + 28)
        crc = int(_U32.unpack_from(head, 9 + 24)[0])
        data_offset = offset + 9 + 28 + 4 + len(compression.encode()) + 8
        indexes = {}
        for channel, at in positions.items():
            opcode, size = _REC.unpack(self._read(at, 9))
            if opcode != 0x07:
                msg = f'{self.what}: message index offset {at} does not point at one'
                raise BagReadError(msg)
            indexes[channel] = (at, size)
        return _Chunk(offset, data_offset, compressed, uncompressed, crc, compression, indexes)

    def _count_from_indexes(self) -> None:
        for block in self.blocks:
            if isinstance(block, _Loose):
                continue
            for channel, (_, size) in (block.indexes or {}).items():
                self.counts[channel] = self.counts.get(channel, 0) + (size - 6) // 16

    def _scan(self) -> None:
        """Walk the data section record by record; stop at the first incomplete record."""
        pos = self.data_start
        closed = False
        last_chunk: _Chunk | None = None
        while True:
            if pos + 9 > self.size:
                self._cut(pos, 'inside a record header' if pos < self.size else '')
                break
            opcode, length = _REC.unpack(self._read(pos, 9))
            end = pos + 9 + length
            if end > self.size:
                self._cut(pos, f'inside a record of {length} bytes')
                break
            if opcode == 0x06:
                last_chunk = self._scan_chunk(pos, length)
                self.blocks.append(last_chunk)
            elif opcode == 0x07 and last_chunk is not None and last_chunk.indexes is not None:
                channel = _U16.unpack(self._read(pos + 9, 2))[0]
                last_chunk.indexes[channel] = (pos, length)
            elif opcode == 0x05:
                self.blocks.append(_Loose(pos, length))
            elif opcode == 0x0C:
                self.metadata_at.append((pos, 9 + length))
            elif opcode == 0x03:
                self._schema(self._read(pos + 9, length))
            elif opcode == 0x04:
                self._channel(self._read(pos + 9, length))
            elif opcode in (0x0F, 0x02):  # Data End, or a Footer right after the data
                closed = True
                break
            elif opcode == 0x00:
                msg = f'{self.what}: corrupt record (opcode 0) at byte {pos}'
                raise BagReadError(msg)
            pos = end
        if self.summary_damaged:
            self.truncated = True
            self.reason = 'its MCAP summary is damaged; the data section was scanned instead'
        elif not self.truncated and closed:
            self.truncated = True
            self.reason = 'the bag was not closed (no MCAP summary): its writer was stopped'
        if last_chunk is not None and not closed:
            last_chunk.indexes = None  # its message indexes may be incomplete: rescan it
        self._channels_from_chunks()
        self._count_from_indexes()
        for block in self.blocks:
            if isinstance(block, _Loose):
                channel = _U16.unpack(self._read(block.offset + 9, 2))[0]
                self.counts[channel] = self.counts.get(channel, 0) + 1
            elif block.indexes is None:
                for channel, _, _ in _records(self.inflate(block), self.what):
                    self.counts[channel] = self.counts.get(channel, 0) + 1

    def _channels_from_chunks(self) -> None:
        """Other writers keep Schema and Channel records inside chunks: find missing ones."""
        chunks = [b for b in self.blocks if isinstance(b, _Chunk)]
        if not any(b.indexes is None or set(b.indexes) - set(self.channels) for b in chunks):
            return
        for chunk in chunks:
            raw = self.inflate(chunk)
            for opcode, pos, length in _chunk_records(raw, self.what):
                if opcode == 0x03:
                    self._schema(raw[pos + 9:pos + 9 + length])
                elif opcode == 0x04:
                    self._channel(raw[pos + 9:pos + 9 + length])
            if not any(b.indexes is None or set(b.indexes) - set(self.channels) for b in chunks):
                return

    def _cut(self, pos: int, where: str) -> None:
        self.truncated = True
        at = f', {where} at {pos}' if where else ''
        self.reason = f'the file ends at byte {self.size}{at}'

    def _scan_chunk(self, pos: int, length: int) -> _Chunk:
        head = self._read(pos + 9, min(length, 28 + 4 + 64))
        rd = _Reader(head, self.what)
        rd.take(16)
        uncompressed, crc = rd.u64(), rd.u32()
        compression = rd.string()
        compressed = rd.u64()
        data_offset = pos + 9 + rd.pos
        if data_offset + compressed > pos + 9 + length:
            msg = f'{self.what}: chunk at byte {pos} is larger than its record'
            raise BagReadError(msg)
        return _Chunk(pos, data_offset, compressed, uncompressed, crc, compression)

    def _schema(self, body: bytes) -> None:
        rd = _Reader(body, self.what)
        schema_id = rd.u16()
        self.schemas[schema_id] = rd.string()

    def _channel(self, body: bytes) -> None:
        rd = _Reader(body, self.what)
        channel_id, schema_id = rd.u16(), rd.u16()
        topic, encoding = rd.string(), rd.string()
        self.channels[channel_id] = _Channel(
            channel_id, topic, schema_id, encoding, rd.string_map(),
        )

    # ------------------------------------------------------------------ data

    def msgtype(self, channel_id: int) -> str:
        return self.schemas.get(self.channels[channel_id].schema_id, '')

    def inflate(self, chunk: _Chunk) -> bytes:
        """Decompress one chunk and check its size and CRC."""
        where = f'{self.what}: chunk at byte {chunk.offset}'
        if chunk.uncompressed_size > MAX_CHUNK:
            msg = f'{where} claims {chunk.uncompressed_size} bytes (corrupt)'
            raise BagReadError(msg)
        decompress = _DECOMPRESSORS.get(chunk.compression)
        if decompress is None:
            msg = f'{where} uses unsupported compression {chunk.compression!r}'
            raise BagReadError(msg)
        data = self._read(chunk.data_offset, chunk.compressed_size)
        try:
            raw = decompress(data, chunk.uncompressed_size)
        except Exception as err:
            msg = f'{where} does not decompress ({err})'
            raise BagReadError(msg) from err
        if len(raw) != chunk.uncompressed_size:
            msg = f'{where} has {len(raw)} bytes, expected {chunk.uncompressed_size} (corrupt)'
            raise BagReadError(msg)
        checked = _self_checked(data, chunk.compression)
        if chunk.crc and not checked and crc32(raw) != chunk.crc:
            msg = f'{where} fails its CRC check (corrupt)'
            raise BagReadError(msg)
        return raw

    def index_offsets(self, chunk: _Chunk, channel: int) -> npt.NDArray[np.int64] | None:
        """Offsets of ``channel``'s records in the chunk from its Message Index."""
        if chunk.indexes is None:
            return None
        if channel not in chunk.indexes:
            return np.zeros(0, np.int64)
        at, length = chunk.indexes[channel]
        body = self._read(at + 9, length)
        size = int(_U32.unpack_from(body, 2)[0])
        if size % 16 or 6 + size > length:
            msg = f'{self.what}: message index at byte {at} is corrupt'
            raise BagReadError(msg)
        pairs = np.frombuffer(body, '<u8', count=size // 8, offset=6).reshape(-1, 2)
        offsets = pairs[:, 1].astype(np.int64)
        if len(offsets) > 1 and not bool((offsets[1:] > offsets[:-1]).all()):
            offsets = np.sort(offsets)
        return offsets

    def close(self) -> None:
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1


def _zstd(data: bytes, size: int) -> bytes:
    import zstandard

    content = zstandard.frame_content_size(data)
    if content > MAX_CHUNK:
        msg = f'zstd frame claims {content} bytes'
        raise BagReadError(msg)
    return bytes(zstandard.ZstdDecompressor().decompress(data, max_output_size=size + 1))


def _lz4(data: bytes, size: int) -> bytes:
    import lz4.frame

    return bytes(lz4.frame.LZ4FrameDecompressor().decompress(data, max_length=size + 1))


_DECOMPRESSORS: dict[str, Callable[[bytes, int], bytes]] = {
    '': lambda data, size: data,
    'zstd': _zstd,
    'lz4': _lz4,
}


def _self_checked(data: bytes, compression: str) -> bool:
    """True if the zstd/lz4 frame carries a content checksum that decompression verified."""
    return compression in ('zstd', 'lz4') and len(data) > 4 and bool(data[4] & 0x04)


def _chunk_records(raw: bytes, what: str) -> Iterator[tuple[int, int, int]]:
    """(opcode, offset, record length) of every record in a decompressed chunk."""
    pos, size = 0, len(raw)
    while pos < size:
        if pos + 9 > size:
            msg = f'{what}: chunk content ends inside a record'
            raise BagReadError(msg)
        opcode, length = _REC.unpack_from(raw, pos)
        if pos + 9 + length > size:
            msg = f'{what}: chunk record runs past the chunk'
            raise BagReadError(msg)
        yield opcode, pos, length
        pos += 9 + length


def _records(raw: bytes, what: str) -> Iterator[tuple[int, int, int]]:
    """(channel, offset, record length) of every Message record in a decompressed chunk."""
    for opcode, pos, length in _chunk_records(raw, what):
        if opcode == 0x05:
            if length < 22:
                msg = f'{what}: message record of {length} bytes is too short'
                raise BagReadError(msg)
            yield int(_U16.unpack_from(raw, pos + 9)[0]), pos, length


# --------------------------------------------------------------------------- the bag


class Bag(Closing):
    """An open bag: topics with counts, truncation state, message streams."""

    def __init__(self, path: Path, files: list[_McapFile], metadata: dict[str, Any] | None):
        """Use :func:`open_bag`."""
        self.path = path
        self.files = files
        self.metadata = metadata
        """The ``rosbag2_bagfile_information`` mapping of ``metadata.yaml``, if any."""
        reasons = [f'{f.path.name}: {f.reason}' for f in files if f.truncated]
        self.truncated = bool(reasons)
        """True if a file was not closed cleanly; only its readable prefix is used."""
        self.truncation_reason = '; '.join(reasons)
        self.topics: dict[str, TopicInfo] = {}
        for mf in files:
            for channel in mf.channels.values():
                old = self.topics.get(channel.topic)
                count = mf.counts.get(channel.id, 0) + (old.message_count if old else 0)
                self.topics[channel.topic] = TopicInfo(
                    channel.topic,
                    mf.msgtype(channel.id),
                    count,
                    channel.metadata.get('offered_qos_profiles', ''),
                    channel.metadata.get('topic_type_hash', ''),
                )

    @property
    def message_count(self) -> int:
        """Messages in the readable part of the bag."""
        return sum(t.message_count for t in self.topics.values())

    @property
    def joint_state_topics(self) -> list[str]:
        """Topics of type ``sensor_msgs/msg/JointState``."""
        return [t.name for t in self.topics.values() if t.msgtype == TYPE_JOINT_STATE]

    def messages(self, topics: Iterable[str] | None = None) -> Iterator[tuple[str, int, bytes]]:
        """Yield (topic, log time ns, serialized bytes) in file order, one chunk in memory."""
        wanted = None if topics is None else set(topics)
        for mf in self.files:
            with _boundary(mf.what):
                ids = {
                    c.id: c.topic for c in mf.channels.values()
                    if wanted is None or c.topic in wanted
                }
            for block in mf.blocks:
                with _boundary(mf.what):
                    items = list(_block_messages(mf, block, ids))
                yield from items

    def metadata_records(self, name: str | None = None) -> list[tuple[str, dict[str, str]]]:
        """(name, string map) of the MCAP Metadata records (all, or those named ``name``),
        from the summary's index or, in a file without one, from the scanned data section."""
        out = []
        for mf in self.files:
            with _boundary(mf.what):
                for offset, length in mf.metadata_at:
                    raw = mf._read(offset, length)
                    if raw[0] != 0x0C or _U64.unpack_from(raw, 1)[0] != length - 9:
                        msg = f'{mf.what}: metadata index at byte {offset} does not point at one'
                        raise BagReadError(msg)
                    rd = _Reader(raw[9:], mf.what)
                    key = rd.string()
                    if name is None or key == name:
                        out.append((key, rd.string_map()))
        return out

    def close(self) -> None:
        """Close the files."""
        for mf in self.files:
            mf.close()


def _block_messages(
    mf: _McapFile,
    block: _Chunk | _Loose,
    ids: dict[int, str],
) -> Iterator[tuple[str, int, bytes]]:
    if isinstance(block, _Loose):
        body = mf._read(block.offset + 9, block.length)
        channel, _, log_time, _ = _MSG.unpack_from(body)
        if channel in ids:
            yield ids[channel], int(log_time), body[22:]
        return
    if block.indexes is not None and not any(c in block.indexes for c in ids):
        return
    raw = mf.inflate(block)
    if block.indexes is not None and len(ids) < len(mf.channels):  # a few topics: index
        found = []
        for c in ids:
            at = mf.index_offsets(block, c)
            found += [(int(o), c) for o in (at if at is not None else ())]
        for pos, channel in sorted(found):
            for log_time, data in _messages_at(mf.what, raw, np.array([pos]), channel):
                yield ids[channel], log_time, data
        return
    for channel, pos, length in _records(raw, mf.what):
        if channel in ids:
            log_time = _U64.unpack_from(raw, pos + 15)[0]
            yield ids[channel], int(log_time), raw[pos + 31:pos + 9 + length]


def _file_order(path: Path) -> tuple[str, int]:
    """Sort key of split files: ``bag_2.mcap`` before ``bag_10.mcap``."""
    stem, _, index = path.stem.rpartition('_')
    return (stem, int(index)) if index.isdigit() else (path.stem, -1)


def _bag_files(path: Path) -> tuple[Path, list[Path], dict[str, Any] | None]:
    """Resolve a bag path to its MCAP files and parsed metadata."""
    import yaml

    if not path.exists():
        msg = f'{path}: no such file or directory'
        raise BagReadError(msg)
    if path.is_file() and path.name == 'metadata.yaml':
        path = path.parent
    if path.is_file():
        return path, [path], None
    metadata = None
    meta_path = path / 'metadata.yaml'
    if meta_path.is_file():
        try:
            text = meta_path.read_text(encoding='utf-8', errors='replace')
            loaded = yaml.load(text, Loader=getattr(yaml, 'CSafeLoader', yaml.SafeLoader))
            metadata = loaded['rosbag2_bagfile_information']
            if not isinstance(metadata, dict):
                raise TypeError('not a mapping')
        except (OSError, yaml.YAMLError, KeyError, TypeError, RecursionError):
            metadata = None  # unreadable metadata.yaml: the MCAP alone is the bag
    if metadata is not None:
        storage = metadata.get('storage_identifier', 'mcap')
        if storage != 'mcap':
            msg = f'{path}: storage {storage!r} is not supported, only mcap bags can be read'
            raise BagReadError(msg)
        names = [Path(str(p)).name for p in metadata.get('relative_file_paths') or []]
        files = [path / n for n in names]
        if missing := [f.name for f in files if not f.is_file()]:
            msg = f'{path}: metadata.yaml lists {", ".join(missing)} but it is missing'
            raise BagReadError(msg)
        if files:
            return path, files, metadata
    files = sorted(path.glob('*.mcap'), key=_file_order)
    if not files:
        msg = f'{path}: no metadata.yaml and no .mcap file, not a rosbag2 bag directory'
        raise BagReadError(msg)
    return path, files, metadata


def open_bag(path: str | os.PathLike[str], *, require_joint_states: bool = True) -> Bag:
    """Open a bag directory or ``.mcap`` file; raise :class:`BagReadError` if unusable.

    With ``require_joint_states`` a bag without any JointState topic is refused too.
    """
    where = str(path)
    files: list[_McapFile] = []
    with _boundary(where):
        root, paths, metadata = _bag_files(Path(path))
        try:
            files.extend(_McapFile(p) for p in paths)
        except BaseException:
            for mf in files:
                mf.close()
            raise
        bag = Bag(root, files, metadata)
    if require_joint_states and not bag.joint_state_topics:
        bag.close()
        if not bag.topics:
            msg = f'{where}: the bag has no topics' + (
                f' ({bag.truncation_reason})' if bag.truncated else ''
            )
        else:
            msg = f'{where}: no {TYPE_JOINT_STATE} topic (topics: {", ".join(bag.topics)})'
        raise BagReadError(msg)
    return bag


# --------------------------------------------------------------------------- JointStates


def _check_topics(bag: Bag, topics: Sequence[str]) -> None:
    for topic in topics:
        info = bag.topics.get(topic)
        if info is None:
            msg = f'{bag.path}: no topic {topic} (topics: {", ".join(bag.topics) or "none"})'
            raise BagReadError(msg)
        if info.msgtype != TYPE_JOINT_STATE:
            msg = f'{bag.path}: topic {topic} has type {info.msgtype}, not {TYPE_JOINT_STATE}'
            raise BagReadError(msg)


def iter_joint_state_blocks(
    bag: Bag,
    topics: Sequence[str],
    *,
    prefetch: int = 2,
    frames: dict[str, list[tuple[int, str]]] | None = None,
    others: dict[str, list[tuple[int, bytes]]] | None = None,
) -> Iterator[tuple[str, JointStateArrays]]:
    """Yield (topic, arrays) chunk by chunk in file order, decoding all ``topics`` in one
    pass. A helper thread reads and decompresses up to ``prefetch`` chunks ahead (the
    decompressors release the GIL), so memory stays bounded by a few chunks.

    ``frames``: for each topic that is a key, the (stamp ns, frame_id) of every message
    whose header.frame_id differs from the one before it are appended to its list before
    the block is yielded (vectorised, see :meth:`JointStateDecoder.frame_changes`).
    ``others``: for each topic that is a key (of any type; absent topics are skipped), its
    (log time ns, serialized bytes) are appended in the same pass (one read of the bag)."""
    _check_topics(bag, topics)
    decoders = {topic: JointStateDecoder() for topic in topics}
    for topic, found in (frames or {}).items():
        decoders[topic].frame_log = found
    extra = others or {}
    for mf in bag.files:
        with _boundary(mf.what):
            ids = {c.id: c.topic for c in mf.channels.values()
                   if c.topic in decoders or c.topic in extra}
        blocks = [
            b for b in mf.blocks
            if isinstance(b, _Loose) or b.indexes is None or any(c in b.indexes for c in ids)
        ]
        for loaded in _prefetched(mf, blocks, ids, prefetch):
            with _boundary(mf.what):
                out = list(_decode_loaded(mf, loaded, ids, decoders, extra))
            yield from out


_Loaded = tuple[bytes, dict[int, npt.NDArray[np.int64]]]


def _prefetched(
    mf: _McapFile,
    blocks: list[_Chunk | _Loose],
    ids: dict[int, str],
    depth: int,
) -> Iterator[_Loaded | _Loose]:
    """Load blocks (read, inflate, index) in order, ``depth`` ahead in a helper thread."""
    if depth <= 0:
        for block in blocks:
            with _boundary(mf.what):
                loaded = _load(mf, block, ids)
            yield loaded
        return
    pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix='bag-prefetch')
    pending: deque[Future[_Loaded | _Loose]] = deque()
    try:
        queue = iter(blocks)
        for block in queue:
            pending.append(pool.submit(_load, mf, block, ids))
            if len(pending) > depth:
                break
        while pending:
            with _boundary(mf.what):
                loaded = pending.popleft().result()
            for block in queue:
                pending.append(pool.submit(_load, mf, block, ids))
                break
            yield loaded
    finally:
        for future in pending:
            future.cancel()
        pool.shutdown(wait=True)


def _load(mf: _McapFile, block: _Chunk | _Loose, ids: dict[int, str]) -> _Loaded | _Loose:
    """Read and inflate a chunk and find the record offsets of the wanted channels."""
    if isinstance(block, _Loose):
        return block
    raw = mf.inflate(block)
    if block.indexes is None:  # no (complete) message index: walk the records
        scanned: dict[int, list[int]] = {c: [] for c in ids}
        for channel, pos, _ in _records(raw, mf.what):
            if channel in scanned:
                scanned[channel].append(pos)
        return raw, {c: np.asarray(v, np.int64) for c, v in scanned.items() if v}
    found = {c: mf.index_offsets(block, c) for c in ids if c in block.indexes}
    return raw, {c: v for c, v in found.items() if v is not None and len(v)}


def _decode_loaded(
    mf: _McapFile,
    loaded: _Loaded | _Loose,
    ids: dict[int, str],
    decoders: dict[str, JointStateDecoder],
    others: dict[str, list[tuple[int, bytes]]],
) -> Iterator[tuple[str, JointStateArrays]]:
    if isinstance(loaded, _Loose):
        for topic, log_time, data in _block_messages(mf, loaded, ids):
            if topic in decoders:
                yield topic, _slow(decoders[topic], [data])
            else:
                others[topic].append((log_time, data))
        return
    raw, offsets = loaded
    buf = np.frombuffer(raw, np.uint8)
    for channel, found in offsets.items():
        topic = ids[channel]
        if topic in decoders:
            yield topic, _decode_records(mf.what, buf, found, channel, decoders[topic])
        else:
            others[topic].extend(_messages_at(mf.what, raw, found, channel))


def _messages_at(
    what: str, raw: bytes, offsets: npt.NDArray[np.int64], channel: int,
) -> Iterator[tuple[int, bytes]]:
    """(log time, bytes) of ``channel``'s Message records at ``offsets`` of a chunk."""
    for pos in offsets.tolist():
        if pos + 31 > len(raw) or raw[pos] != 5:
            msg = f'{what}: message index does not match the chunk records (corrupt)'
            raise BagReadError(msg)
        length, got = _U64.unpack_from(raw, pos + 1)[0], _U16.unpack_from(raw, pos + 9)[0]
        if got != channel or length < 22 or pos + 9 + length > len(raw):
            msg = f'{what}: message index does not match the chunk records (corrupt)'
            raise BagReadError(msg)
        log_time = _U64.unpack_from(raw, pos + 15)[0]
        yield int(log_time), raw[pos + 31:pos + 9 + length]


def _decode_records(
    what: str,
    buf: npt.NDArray[np.uint8],
    offsets: npt.NDArray[np.int64],
    channel: int,
    decoder: JointStateDecoder,
) -> JointStateArrays:
    """Check one channel's Message records in a chunk, then decode them vectorised."""
    if int(offsets[0]) < 0 or int(offsets[-1]) + 31 > len(buf):
        msg = f'{what}: message index points outside its chunk'
        raise BagReadError(msg)
    head = cdr.gather_rows(buf, offsets, 31)
    lengths = head[:, 1:9].view('<u8')[:, 0].astype(np.int64)
    if not (
        bool((head[:, 0] == 5).all())
        and bool((head[:, 9:11].view('<u2')[:, 0] == channel).all())
        and bool((lengths >= 22).all())
        and int((offsets + 9 + lengths).max()) <= len(buf)
    ):
        msg = f'{what}: message index does not match the chunk records (corrupt)'
        raise BagReadError(msg)
    arrays = decoder.decode(buf, offsets + 31, lengths - 22)
    if decoder.frame_log is not None:
        changes = decoder.frame_changes(buf, offsets + 31, lengths - 22)
        decoder.frame_log.extend((int(arrays.stamps[i]), frame) for i, frame in changes)
    return arrays


def _slow(decoder: JointStateDecoder, messages: list[bytes]) -> JointStateArrays:
    """Decode messages stored outside chunks."""
    sizes = np.array([len(m) for m in messages], np.int64)
    starts = np.concatenate(([0], np.cumsum(sizes)[:-1])).astype(np.int64)
    buf = np.frombuffer(b''.join(messages), np.uint8)
    arrays = decoder.decode(buf, starts, sizes)
    if decoder.frame_log is not None:
        changes = decoder.frame_changes(buf, starts, sizes)
        decoder.frame_log.extend((int(arrays.stamps[i]), frame) for i, frame in changes)
    return arrays


def read_joint_state_topics(bag: Bag, topics: Sequence[str]) -> dict[str, JointStateArrays]:
    """Decode several JointState topics in one pass into whole-run arrays per topic.

    The arrays are allocated once from the topic counts and filled chunk by chunk; only a
    few chunks of raw data are in memory at a time.
    """
    _check_topics(bag, topics)
    names: dict[str, tuple[str, ...]] = {}
    arrays: dict[str, list[npt.NDArray[Any]]] = {}
    filled = dict.fromkeys(topics, 0)
    most = sum(mf.size for mf in bag.files) // 31  # a Message record has at least 31 bytes
    with _boundary(str(bag.path)):
        for topic, (stamps, block_names, *values) in iter_joint_state_blocks(bag, topics):
            start, stop = filled[topic], filled[topic] + len(stamps)
            if topic not in arrays:
                count = min(bag.topics[topic].message_count, most)
                n, k = max(count, stop), len(block_names)
                names[topic] = block_names
                arrays[topic] = [np.empty(n, np.int64), *(np.empty((n, k)) for _ in range(3))]
            out = arrays[topic]
            if stop > len(out[0]):  # the counts were low (damaged statistics): grow
                out[:] = [np.resize(a, (2 * stop, *a.shape[1:])) for a in out]
            for dest, src in zip(out, (stamps, *values), strict=True):
                dest[start:stop] = src
            filled[topic] = stop
    result = {}
    for topic in topics:
        if topic in arrays:
            n = filled[topic]
            stamps, pos, vel, eff = (a[:n] for a in arrays[topic])
            result[topic] = JointStateArrays(stamps, names[topic], pos, vel, eff)
        else:
            empty = np.zeros((0, 0))
            result[topic] = JointStateArrays(np.zeros(0, np.int64), (), empty, empty, empty)
    return result


def read_joint_state_arrays(bag: Bag, topic: str) -> JointStateArrays:
    """(stamps ns, names, position, velocity, effort) of one JointState topic."""
    return read_joint_state_topics(bag, [topic])[topic]
