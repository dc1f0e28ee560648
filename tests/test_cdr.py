"""The one CDR codec (hexapod_common/core/cdr.py): rclpy's bytes, the vectorised decoder against
the per-message one, DDS padding, and the nodes' per-topic codec."""

from __future__ import annotations

import numpy as np
import pytest
from hexapod_common.core import cdr
from hexapod_common.core import topics as T
from hexapod_common.core.errors import CdrError

LEGS = [f'leg{i}_{j}' for i in range(1, 7) for j in ('hip', 'knee')]
TYPE_JOINT_STATE = 'sensor_msgs/msg/JointState'


def _status(i: int) -> list[cdr.DiagnosticStatus]:
    values = (('e_x', f'{0.1 * i:.3f}'),)
    return [cdr.DiagnosticStatus('cycle', f'cycle {i}', 'hexapod', 0, values)]


def test_cdr_equals_rclpy_serialize_message() -> None:
    try:
        from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
        from rclpy.serialization import serialize_message
        from rosgraph_msgs.msg import Clock
        from sensor_msgs.msg import JointState
        from std_msgs.msg import String
    except ImportError as err:
        pytest.skip(f'rclpy or its messages are not importable ({err}); rclpy equality unchecked')
    rng = np.random.default_rng(11)

    def same(ours: bytes, theirs: bytes, msgtype: str) -> None:
        # rclpy leaves alignment padding uninitialised; ours is zero: compare the rest
        assert len(ours) == len(theirs)
        pad = np.frombuffer(cdr.cdr_padding_mask(theirs, msgtype), np.uint8).astype(bool)
        a, b = np.frombuffer(ours, np.uint8), np.frombuffer(theirs, np.uint8)
        np.testing.assert_array_equal(a[~pad], b[~pad])
        assert not a[pad].any()

    for _ in range(100):
        k = int(rng.integers(0, 13))
        names = [f'j{"x" * int(rng.integers(0, 9))}{i}' for i in range(k)]
        frame = 'f' * int(rng.integers(0, 7))
        arrays = [rng.standard_normal(int(rng.choice([0, k]))) for _ in range(3)]
        stamp = int(rng.integers(0, 2**31)) * 1_000_000_000 + int(rng.integers(0, 1_000_000_000))
        msg = JointState(name=names, position=arrays[0].tolist(), velocity=arrays[1].tolist(),
                         effort=arrays[2].tolist())
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp, 1_000_000_000)
        msg.header.frame_id = frame
        theirs = serialize_message(msg)
        ours = cdr.encode_joint_state(stamp, names, *arrays, frame_id=frame)
        same(ours, theirs, TYPE_JOINT_STATE)
        decoded = cdr.decode_joint_state(theirs)
        assert (decoded.stamp_ns, decoded.names, decoded.frame_id) == (stamp, tuple(names), frame)
        text = 'ü' * int(rng.integers(0, 5)) + 'pd_pf'[: int(rng.integers(0, 6))]
        same(cdr.encode_string(text), serialize_message(String(data=text)), 'std_msgs/msg/String')
        clock = Clock()
        clock.clock.sec, clock.clock.nanosec = divmod(stamp, 1_000_000_000)
        same(cdr.encode_clock(stamp), serialize_message(clock), 'rosgraph_msgs/msg/Clock')
        statuses = _status(int(rng.integers(0, 50)))[: int(rng.integers(0, 2))]
        array = DiagnosticArray(status=[
            DiagnosticStatus(level=bytes([s.level]), name=s.name, message=s.message,
                             hardware_id=s.hardware_id,
                             values=[KeyValue(key=a, value=b) for a, b in s.values])
            for s in statuses
        ])
        array.header.stamp.sec, array.header.stamp.nanosec = divmod(stamp, 1_000_000_000)
        same(cdr.encode_diagnostic_array(stamp, statuses), serialize_message(array),
             'diagnostic_msgs/msg/DiagnosticArray')


def test_fast_decoder_equals_slow_decoder() -> None:
    rng = np.random.default_rng(5)
    messages = []
    for i in range(2000):
        frame = 'base' if i % 97 else 'base_link'  # a different layout now and then
        values = rng.standard_normal((3, 12))
        effort = values[2] if i % 101 else []  # an empty array: the per-message path
        raw = bytearray(cdr.encode_joint_state(i * 7, LEGS, values[0], values[1], effort, frame))
        pad = np.frombuffer(cdr.cdr_padding_mask(bytes(raw), TYPE_JOINT_STATE), np.uint8)
        for at in np.flatnonzero(pad):  # garbage padding, as rclpy leaves it
            raw[at] = int(rng.integers(0, 256))
        messages.append(bytes(raw))
    fast = cdr.decode_joint_state_batch(messages)
    for i in range(0, 2000, 7):
        slow = cdr.decode_joint_state(messages[i])
        assert fast.stamps[i] == slow.stamp_ns
        np.testing.assert_array_equal(fast.position[i], slow.position)
        np.testing.assert_array_equal(fast.velocity[i], slow.velocity)
        if len(slow.effort):
            np.testing.assert_array_equal(fast.effort[i], slow.effort)
        else:
            assert np.isnan(fast.effort[i]).all()
    with pytest.raises(CdrError, match='joint names changed'):
        swapped = cdr.encode_joint_state(0, LEGS[::-1], *rng.standard_normal((3, 12)))
        cdr.decode_joint_state_batch([*messages, swapped])


@pytest.mark.parametrize(("text", "pad"), [("pd_p", 3), ("pd_pf", 2), ("abcdef", 1)])
def test_decoder_accepts_dds_padding(text: str, pad: int) -> None:
    data = cdr.encode_string(text)
    assert (len(data) + pad) % 4 == 0  # what DDS appends to reach a multiple of 4
    assert cdr.decode_string(data + bytes(pad)) == text
    status = cdr.DiagnosticStatus("n", "m", "h", 2, (("k", text),))
    arr = cdr.encode_diagnostic_array(7, [status])
    assert len(arr) % 4 and cdr.decode_diagnostic_array(arr + bytes(-len(arr) % 4)) == (
        7, [status])


def test_decoder_rejects_what_is_not_padding() -> None:
    data = cdr.encode_string("pd_pf")
    with pytest.raises(CdrError, match="4 unexpected trailing bytes"):
        cdr.decode_string(data + bytes(4))
    with pytest.raises(CdrError, match="unexpected trailing bytes"):
        cdr.decode_string(data + b"\x01")


@pytest.mark.parametrize('topic', sorted(cdr.CODECS))
def test_codec_is_the_encoder_and_decodes_views(topic: str) -> None:
    codec = cdr.CODECS[topic]
    rng = np.random.default_rng(3)
    pos, vel, eff = rng.standard_normal((3, codec.n))
    for frame in ('', 'pd_p', 'pd_pf', 'fallback'):
        data = codec.encode(123_456_789_012, frame, pos, vel, eff)
        assert data == cdr.encode_joint_state(123_456_789_012, codec.names, pos, vel, eff, frame)
        view = codec.decode(data)
        assert (view.stamp_ns, view.frame_id) == (123_456_789_012, frame)
        np.testing.assert_array_equal(view.effort, eff)
        assert not view.position.flags.writeable  # the fast path: views into the bytes


def test_codec_accepts_dds_padding_and_garbage_padding() -> None:
    codec = cdr.CODECS[T.JOINT_STATES]
    pos = np.arange(12.0)
    data = codec.encode(7, 'pd_pf', pos, pos, pos)
    padded = data + bytes(-len(data) % 4 or 4)[:3]
    assert codec.decode(padded).frame_id == 'pd_pf'
    raw = bytearray(data)
    mask = np.frombuffer(cdr.cdr_padding_mask(data, TYPE_JOINT_STATE), np.uint8)
    for at in np.flatnonzero(mask):
        raw[at] = 0xAA  # what rclpy may leave in alignment padding
    np.testing.assert_array_equal(codec.decode(bytes(raw)).velocity, pos)


@pytest.mark.parametrize(('mutate', 'match'), [
    (lambda d: d[:40], 'too short|does not carry|not a serialized'),
    (lambda d: d + bytes(8), 'unexpected trailing bytes'),
    (lambda d: b'\x00\x00' + d[2:], 'not little-endian CDR'),
    (lambda d: d[:16] + b'\xff\xfe' + d[18:], 'not a serialized JointState'),
])
def test_codec_refuses_with_one_line(mutate: object, match: str) -> None:
    codec = cdr.CODECS[T.JOINT_STATES]
    pos = np.zeros(12)
    data = codec.encode(7, 'pd_pf', pos, pos, pos)
    with pytest.raises(CdrError, match=match) as info:
        codec.decode(mutate(data))  # type: ignore[operator]
    assert '\n' not in str(info.value)
    with pytest.raises(CdrError, match='does not carry'):
        cdr.CODECS[T.REFERENCE].decode(data)  # the joints of another topic
