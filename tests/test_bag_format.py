"""Bag format: our writer and reader against rosbags, mcap, mcap-ros2-support and rclpy."""

from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import yaml
from hexapod_metrics.bag import (
    BagReadError,
    BagWriteError,
    BagWriter,
    QosProfile,
    iter_joint_state_blocks,
    open_bag,
    qos_yaml,
    read_joint_state_arrays,
    read_joint_state_topics,
)
from hexapod_metrics.bag.msgdefs import MESSAGE_TYPES, TYPE_JOINT_STATE
from hexapod_common.core import cdr

from killed_writer import write_then_kill

LEGS = [f'leg{i}_{j}' for i in range(1, 7) for j in ('hip', 'knee')]
FEET = [f'leg{i}_foot_{a}' for i in range(1, 7) for a in ('x', 'y')]
JS, FF = '/hexapod/joint_states', '/hexapod/foot_forces'
CTRL, IDX, CLOCK = '/hexapod/active_controller', '/hexapod/indices', '/clock'
T0 = 1_000_000_000


def _signals(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return tuple(rng.standard_normal((n, 12)) for _ in range(3))  # type: ignore[return-value]


def _status(i: int) -> list[cdr.DiagnosticStatus]:
    values = (('e_x', f'{0.1 * i:.3f}'),)
    return [cdr.DiagnosticStatus('cycle', f'cycle {i}', 'hexapod', 0, values)]


def _write_bag(path: Path, n: int = 3000, **kwargs: object) -> tuple[np.ndarray, ...]:
    """A small graph-like bag: two JointState topics, clock, controller, indices."""
    pos, vel, eff = _signals(n)
    with BagWriter(path, **kwargs) as writer:  # type: ignore[arg-type]
        writer.add_topic(CTRL, 'std_msgs/msg/String', 'transient_local')
        writer.write_string(CTRL, T0, 'pd_p')
        for i in range(n):
            t = T0 + i * 1_000_000
            writer.write_clock(CLOCK, t)
            writer.write_joint_state(JS, t, LEGS, pos[i], vel[i], eff[i])
            frame = 'w' * (i % 3)  # same padded length, another frame_id
            writer.write_joint_state(FF, t, FEET, -pos[i], -vel[i], -eff[i], frame_id=frame)
            if i % 1000 == 999:
                writer.write_diagnostic_array(IDX, t, _status(i))
    return pos, vel, eff


@pytest.fixture(scope='module')
def bag_dir(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, tuple[np.ndarray, ...]]:
    path = tmp_path_factory.mktemp('bags') / 'run1'
    signals = _write_bag(path, chunk_size=64 * 1024)
    return path, signals


# --------------------------------------------------------------------------- round trips


def test_round_trip_with_our_reader(bag_dir: tuple[Path, tuple[np.ndarray, ...]]) -> None:
    path, (pos, vel, eff) = bag_dir
    with open_bag(path) as bag:
        assert not bag.truncated
        assert {t: (i.msgtype, i.message_count) for t, i in bag.topics.items()} == {
            CTRL: ('std_msgs/msg/String', 1),
            CLOCK: ('rosgraph_msgs/msg/Clock', 3000),
            JS: (TYPE_JOINT_STATE, 3000),
            FF: (TYPE_JOINT_STATE, 3000),
            IDX: ('diagnostic_msgs/msg/DiagnosticArray', 3),
        }
        arrays = read_joint_state_topics(bag, [JS, FF])
        js, ff = arrays[JS], arrays[FF]
        assert js.names == tuple(LEGS) and ff.names == tuple(FEET)
        np.testing.assert_array_equal(js.stamps, T0 + np.arange(3000) * 1_000_000)
        np.testing.assert_array_equal(js.position, pos)
        np.testing.assert_array_equal(js.velocity, vel)
        np.testing.assert_array_equal(js.effort, eff)
        np.testing.assert_array_equal(ff.effort, -eff)
        single = read_joint_state_arrays(bag, JS)
        np.testing.assert_array_equal(single.position, pos)
        by_topic: dict[str, list[bytes]] = {}
        for topic, _, data in bag.messages([CTRL, IDX, CLOCK]):
            by_topic.setdefault(topic, []).append(data)
    assert [cdr.decode_string(m) for m in by_topic[CTRL]] == ['pd_p']
    assert cdr.decode_diagnostic_array(by_topic[IDX][1]) == (T0 + 1999 * 1_000_000, _status(1999))
    clocks = [cdr.decode_clock(m) for m in by_topic[CLOCK]]
    assert clocks == list(T0 + np.arange(3000) * 1_000_000)


def test_rosbags_anyreader_reads_everything(bag_dir: tuple[Path, tuple[np.ndarray, ...]]) -> None:
    highlevel = pytest.importorskip('rosbags.highlevel', reason='rosbags is not installed')
    path, (pos, vel, eff) = bag_dir
    with highlevel.AnyReader([path]) as reader:
        counts = {c.topic: (c.msgtype, c.msgcount) for c in reader.connections}
        assert counts[JS] == (TYPE_JOINT_STATE, 3000)
        assert counts[IDX] == ('diagnostic_msgs/msg/DiagnosticArray', 3)
        seen: dict[str, list[object]] = {}
        for connection, _, raw in reader.messages():
            msg = reader.deserialize(raw, connection.msgtype)
            seen.setdefault(connection.topic, []).append(msg)
    counts = {t: len(v) for t, v in seen.items()}
    assert counts == {CTRL: 1, CLOCK: 3000, JS: 3000, FF: 3000, IDX: 3}
    js = seen[JS]
    np.testing.assert_array_equal(np.array([m.position for m in js]), pos)  # type: ignore[attr-defined]
    np.testing.assert_array_equal(np.array([m.velocity for m in js]), vel)  # type: ignore[attr-defined]
    np.testing.assert_array_equal(np.array([m.effort for m in js]), eff)  # type: ignore[attr-defined]
    assert list(js[5].name) == LEGS  # type: ignore[attr-defined]
    assert seen[CTRL][0].data == 'pd_p'  # type: ignore[attr-defined]
    status = seen[IDX][0].status[0]  # type: ignore[attr-defined]
    value = status.values[0]
    assert (status.name, value.key, value.value) == ('cycle', 'e_x', '99.900')


def test_mcap_reader_and_ros2_decoder(bag_dir: tuple[Path, tuple[np.ndarray, ...]]) -> None:
    reader_mod = pytest.importorskip('mcap.reader', reason='mcap is not installed')
    decoder = pytest.importorskip('mcap_ros2.decoder', reason='mcap-ros2-support is not installed')
    path, (pos, _, eff) = bag_dir
    with open(path / 'run1_0.mcap', 'rb') as fh:
        factories = [decoder.DecoderFactory()]
        reader = reader_mod.make_reader(fh, decoder_factories=factories, validate_crcs=True)
        assert reader.get_header().profile == 'ros2'
        summary = reader.get_summary()
        assert summary is not None and summary.statistics.message_count == 9004
        assert {s.encoding for s in summary.schemas.values()} == {'ros2msg'}
        for channel in summary.channels.values():
            assert channel.message_encoding == 'cdr'
            assert set(channel.metadata) == {'offered_qos_profiles', 'topic_type_hash'}
        positions, efforts = [], []
        for _, _, _, msg in reader.iter_decoded_messages(topics=[JS], log_time_order=True):
            positions.append(msg.position)
            efforts.append(msg.effort)
    np.testing.assert_array_equal(np.array(positions), pos)
    np.testing.assert_array_equal(np.array(efforts), eff)


@pytest.mark.parametrize('compression', ['zstd', 'lz4'])
def test_compressed_chunks_read_everywhere(tmp_path: Path, compression: str) -> None:
    highlevel = pytest.importorskip('rosbags.highlevel', reason='rosbags is not installed')
    reader_mod = pytest.importorskip('mcap.reader', reason='mcap is not installed')
    path = tmp_path / compression
    pos, _, _ = _write_bag(path, n=500, compression=compression, chunk_size=16 * 1024)
    with open_bag(path) as bag:
        np.testing.assert_array_equal(read_joint_state_arrays(bag, JS).position, pos)
    with highlevel.AnyReader([path]) as reader:
        rows = [reader.deserialize(raw, c.msgtype).position
                for c, _, raw in reader.messages() if c.topic == JS]
    np.testing.assert_array_equal(np.array(rows), pos)
    with open(path / f'{compression}_0.mcap', 'rb') as fh:
        reader = reader_mod.make_reader(fh, validate_crcs=True)
        count = sum(1 for _ in reader.iter_messages(topics=[JS]))
        assert reader.get_summary().chunk_indexes[0].compression == compression
    assert count == 500


def test_metadata_matches_jazzy_layout_and_channel_qos(
    bag_dir: tuple[Path, tuple[np.ndarray, ...]],
) -> None:
    path, _ = bag_dir
    info = yaml.safe_load((path / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert info['version'] == 9
    assert (info['storage_identifier'], info['ros_distro']) == ('mcap', 'jazzy')
    assert info['relative_file_paths'] == ['run1_0.mcap']
    assert info['message_count'] == 9004 == info['files'][0]['message_count']
    assert info['starting_time']['nanoseconds_since_epoch'] == T0
    assert info['duration']['nanoseconds'] == 2999 * 1_000_000
    assert (info['compression_format'], info['compression_mode']) == ('', '')
    assert info['custom_data'] is None
    topics = {t['topic_metadata']['name']: t for t in info['topics_with_message_count']}
    js = topics[JS]['topic_metadata']
    assert js['type_description_hash'] == MESSAGE_TYPES[TYPE_JOINT_STATE].type_hash
    assert js['offered_qos_profiles'][0]['reliability'] == 'reliable'
    ctrl = topics[CTRL]['topic_metadata']['offered_qos_profiles'][0]
    assert ctrl['durability'] == 'transient_local'
    # rosbags silently drops messages if metadata QoS and MCAP channel QoS differ
    with open_bag(path) as bag:
        for name, topic in topics.items():
            assert yaml.safe_load(bag.topics[name].offered_qos_profiles) == (
                topic['topic_metadata']['offered_qos_profiles']
            )


@pytest.mark.parametrize('msgtype', sorted(MESSAGE_TYPES))
def test_embedded_definitions_parse(msgtype: str) -> None:
    typesys = pytest.importorskip('rosbags.typesys', reason='rosbags is not installed')
    records = pytest.importorskip('mcap.records', reason='mcap is not installed')
    decoder = pytest.importorskip('mcap_ros2.decoder', reason='mcap-ros2-support is missing')
    definition = MESSAGE_TYPES[msgtype].definition
    assert definition.count('\nMSG: ') == len(typesys.get_types_from_msg(definition, msgtype)) - 1
    schema = records.Schema(id=1, name=msgtype, encoding='ros2msg', data=definition.encode())
    assert decoder.DecoderFactory().decoder_for('cdr', schema) is not None
    assert MESSAGE_TYPES[msgtype].type_hash.startswith('RIHS01_')


def test_qos_string_is_yaml_cpp_dump() -> None:
    text = qos_yaml([QosProfile(durability='transient_local')])
    assert text.splitlines()[:4] == [
        '- history: unknown', '  depth: 0', '  reliability: reliable',
        '  durability: transient_local',
    ]
    assert text.endswith('  avoid_ros_namespace_conventions: false')
    assert yaml.safe_load(text)[0]['deadline'] == {'sec': 9223372036, 'nsec': 854775807}


# --------------------------------------------------------------------------- crashes and damage

_KILLED_WRITER = textwrap.dedent('''
    import sys
    import numpy as np
    from hexapod_metrics.bag import BagWriter
    names = [f'j{i}' for i in range(12)]
    w = BagWriter(sys.argv[1], chunk_size=32 * 1024, flush_interval_s=60.0).open()
    w.write_string('/hexapod/active_controller', 0, 'pd_pf')
    i = 0
    while True:
        row = np.arange(12.0) + i
        w.write_joint_state('/hexapod/joint_states', i, names, row, 2 * row, 3 * row)
        i += 1
''')


def test_sigkill_mid_write_leaves_readable_prefix(tmp_path: Path) -> None:
    path = tmp_path / 'killed'
    write_then_kill(_KILLED_WRITER, path, 5 * 16 * 1024)
    mcap_file = path / 'killed_0.mcap'
    meta = yaml.safe_load((path / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    with open_bag(path) as bag:
        # the kill may land between chunks ('not closed') or inside a write (cut record)
        assert bag.truncated and bag.truncation_reason
        arrays = read_joint_state_arrays(bag, '/hexapod/joint_states')
    n = len(arrays.stamps)
    assert n >= 100 and n >= meta['message_count'] - 1  # metadata counts flushed messages
    expected = np.arange(12.0)[None, :] + np.arange(n)[:, None]
    np.testing.assert_array_equal(arrays.stamps, np.arange(n))
    np.testing.assert_array_equal(arrays.position, expected)
    np.testing.assert_array_equal(arrays.effort, 3 * expected)
    highlevel = pytest.importorskip('rosbags.highlevel', reason='rosbags is not installed')
    if mcap_file.read_bytes()[-8:] == b'\x89MCAP0\r\n':
        # the file ends with a footer (the kill did not land inside a write): rosbags reads
        # it as an unindexed MCAP and sees exactly the same prefix
        with highlevel.AnyReader([path]) as reader:
            counts = {c.topic: c.msgcount for c in reader.connections}
            seen = sum(1 for c, _, _ in reader.messages() if c.topic == '/hexapod/joint_states')
        listed = {
            t['topic_metadata']['name']: t['message_count']
            for t in meta['topics_with_message_count']
        }
        assert seen == n and counts['/hexapod/joint_states'] == listed['/hexapod/joint_states']
    else:  # killed inside a write: rosbags needs the end magic and refuses; we don't
        with pytest.raises(Exception, match='magic'), highlevel.AnyReader([path]):
            pass


def test_truncated_at_random_offsets(
    bag_dir: tuple[Path, tuple[np.ndarray, ...]], tmp_path: Path,
) -> None:
    path, (pos, _, _) = bag_dir
    data = (path / 'run1_0.mcap').read_bytes()
    rng = random.Random(7)
    cuts = [*sorted(rng.sample(range(len(data)), 120)), 0, 7, 8, 20, len(data) - 1]
    outcomes = {'data': 0, 'error': 0}
    for cut in cuts:
        file = tmp_path / f'cut{cut}.mcap'
        file.write_bytes(data[:cut])
        try:
            with open_bag(file) as bag:
                assert bag.truncated
                arrays = read_joint_state_arrays(bag, JS)
        except BagReadError as err:
            assert '\n' not in str(err)
            outcomes['error'] += 1
            continue
        outcomes['data'] += 1
        got = len(arrays.stamps)
        if got:
            np.testing.assert_array_equal(arrays.position, pos[:got])
        file.unlink()
    assert outcomes['data'] > 100 and outcomes['error'] >= 3


def test_mutated_bags_fail_cleanly(tmp_path: Path) -> None:
    path = tmp_path / 'small'
    _write_bag(path, n=600, chunk_size=8 * 1024)
    data = (path / 'small_0.mcap').read_bytes()
    rng = random.Random(3)
    results: dict[str, int] = {}
    for trial in range(300):
        raw = bytearray(data)
        kind = trial % 4
        if kind == 0:
            for _ in range(rng.randint(1, 4)):
                raw[rng.randrange(len(raw))] ^= 1 << rng.randrange(8)
        elif kind == 1:
            at = rng.randrange(len(raw))
            raw[at:at + 64] = bytes(len(raw[at:at + 64]))
        elif kind == 2:
            a, b = sorted(rng.sample(range(len(raw)), 2))
            del raw[a:b]
        else:
            raw[rng.randrange(len(raw))] = rng.randrange(256)
        file = tmp_path / 'mutated.mcap'
        file.write_bytes(bytes(raw))
        try:
            with open_bag(file) as bag:
                read_joint_state_topics(bag, bag.joint_state_topics)
                sum(1 for _ in bag.messages())
            outcome = 'read'
        except BagReadError as err:
            assert '\n' not in str(err) and str(err).startswith(str(file))
            outcome = 'error'
        results[outcome] = results.get(outcome, 0) + 1
    assert results.get('error', 0) > 100


@pytest.mark.parametrize(
    ('make', 'match'),
    [
        (lambda p: p.write_bytes(b''), 'empty file'),
        (lambda p: p.write_bytes(random.Random(1).randbytes(5000)), 'not an MCAP file'),
        (lambda p: p.mkdir(), 'no metadata.yaml and no .mcap file'),
        (lambda p: None, 'no such file'),
    ],
    ids=['empty', 'random-bytes', 'empty-dir', 'missing'],
)
def test_not_a_bag(tmp_path: Path, make: object, match: str) -> None:
    target = tmp_path / 'thing.mcap'
    make(target)  # type: ignore[operator]
    with pytest.raises(BagReadError, match=match):
        open_bag(target)


def test_bag_without_joint_states_and_missing_topic(tmp_path: Path) -> None:
    path = tmp_path / 'strings'
    with BagWriter(path) as writer:
        writer.write_string(CTRL, 5, 'pd_p')
    with pytest.raises(BagReadError, match=r'no sensor_msgs/msg/JointState topic \(topics: /hex'):
        open_bag(path)
    with open_bag(path, require_joint_states=False) as bag:
        assert bag.topics[CTRL].message_count == 1
        with pytest.raises(BagReadError, match='has type std_msgs/msg/String'):
            read_joint_state_arrays(bag, CTRL)
        with pytest.raises(BagReadError, match='no topic /nope'):
            read_joint_state_arrays(bag, '/nope')


def test_metadata_written_at_open_and_after_flush(tmp_path: Path) -> None:
    path = tmp_path / 'live'
    writer = BagWriter(path, metadata_interval_s=0.0).open()
    info = yaml.safe_load((path / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert info['message_count'] == 0 and info['topics_with_message_count'] == []
    for i in range(10):
        writer.write_joint_state(JS, i, LEGS, np.zeros(12), np.zeros(12), np.zeros(12))
    writer.flush()
    info = yaml.safe_load((path / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert info['message_count'] == 10
    writer.close()
    writer.close()  # idempotent
    with pytest.raises(BagWriteError, match='closed'):
        writer.write_joint_state(JS, 11, LEGS, np.zeros(12), np.zeros(12), np.zeros(12))


def test_close_from_signal_handler_during_writes(tmp_path: Path) -> None:
    path = tmp_path / 'signalled'
    writer = BagWriter(path, chunk_size=4096).open()
    previous = signal.signal(signal.SIGUSR1, lambda *_: writer.close())
    written = 0
    try:
        for i in range(100_000):
            if i == 500:
                os.kill(os.getpid(), signal.SIGUSR1)
            try:
                writer.write_joint_state(JS, i, LEGS, np.ones(12), np.ones(12), np.ones(12))
            except BagWriteError:
                break
            written += 1
    finally:
        signal.signal(signal.SIGUSR1, previous)
    assert writer.closed and 500 <= written < 100_000
    with open_bag(path) as bag:
        assert not bag.truncated and bag.topics[JS].message_count == written


class _TickError(Exception):
    pass


_ARMED = {'on': False}


def _raise_tick(*_: object) -> None:
    if _ARMED['on']:  # raise only inside the try below, once per arming
        _ARMED['on'] = False
        raise _TickError


def test_exceptions_from_signal_handlers_never_corrupt_the_bag(tmp_path: Path) -> None:
    highlevel = pytest.importorskip('rosbags.highlevel', reason='rosbags is not installed')
    path = tmp_path / 'interrupted'
    writer = BagWriter(path, chunk_size=8 * 1024).open()
    previous = signal.signal(signal.SIGALRM, _raise_tick)
    ticks = 0
    signal.setitimer(signal.ITIMER_REAL, 0.0003, 0.0003)
    try:
        for i in range(20_000):
            row = np.full(12, float(i))
            try:
                _ARMED['on'] = True
                writer.write_joint_state(JS, i, LEGS, row, row, row)
                _ARMED['on'] = False
            except _TickError:
                ticks += 1
    finally:
        _ARMED['on'] = False
        signal.setitimer(signal.ITIMER_REAL, 0, 0)
        signal.signal(signal.SIGALRM, previous)
    writer.close()
    assert ticks > 0
    with open_bag(path) as bag:
        assert not bag.truncated
        arrays = read_joint_state_arrays(bag, JS)
    assert len(arrays.stamps) >= 20_000 - ticks
    np.testing.assert_array_equal(arrays.position[:, 0], arrays.stamps.astype(float))
    np.testing.assert_array_equal(arrays.effort[:, 11], arrays.stamps.astype(float))
    with highlevel.AnyReader([path]) as reader:
        stamps = [reader.deserialize(raw, c.msgtype).header.stamp.nanosec
                  for c, _, raw in reader.messages()]
    assert len(stamps) >= len(arrays.stamps)


def test_writer_refuses_bad_input(tmp_path: Path) -> None:
    writer = BagWriter(tmp_path / 'w')
    with pytest.raises(BagWriteError, match='not open'):
        writer.write(JS, 0, b'')
    with writer:
        with pytest.raises(BagWriteError, match='was not added'):
            writer.write('/other', 0, b'\x00\x01\x00\x00')
        with pytest.raises(BagWriteError, match='fill all three arrays'):
            writer.write_joint_state(JS, 0, LEGS, np.zeros(12), np.zeros(12), [])
        with pytest.raises(BagWriteError, match='unknown message type'):
            writer.add_topic('/x', 'my_msgs/msg/Thing')
    with pytest.raises(BagWriteError, match='not an empty directory'):
        BagWriter(tmp_path / 'w').open()


# --------------------------------------------------------------------------- CDR


def test_streaming_blocks_cover_the_bag(bag_dir: tuple[Path, tuple[np.ndarray, ...]]) -> None:
    path, (pos, _, _) = bag_dir
    with open_bag(path) as bag:
        blocks = [b for t, b in iter_joint_state_blocks(bag, [JS, FF]) if t == JS]
    assert len(blocks) > 5  # several chunks, each decoded on its own
    np.testing.assert_array_equal(np.concatenate([b.position for b in blocks]), pos)


@pytest.mark.parametrize('module', [
    'hexapod_metrics.bag', 'hexapod_metrics.bag.reader', 'hexapod_metrics.bag.writer',
    'hexapod_common.core.cdr', 'hexapod_metrics.bag.msgdefs'])
def test_bag_modules_import_without_rclpy(module: str) -> None:
    code = f'import sys, {module}; print("rclpy" in sys.modules)'
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == 'False'
