"""Message authentication and input checks of the graph's subscribers (no ROS graph needed)."""
from __future__ import annotations

import os
import stat
import time

import numpy as np
import pytest

from hexapod_common.core import msg_checks as M
from hexapod_common.core.msg_auth import (AuthError, Rejected, Signer, TRAILER_BYTES, Verifier,
                                          new_key_file, read_key_file, run_key)


@pytest.fixture
def key() -> bytes:
    return os.urandom(32)


@pytest.mark.parametrize("size", [0, 1, 7, 8, 14, 524])
def test_signed_message_round_trips_and_is_8_byte_aligned(key, size):
    payload = os.urandom(size)
    data = Signer(key, "/t").sign(payload)
    assert len(data) % 8 == 0 and len(data) >= size + TRAILER_BYTES
    assert Verifier(key, "/t").verify(data) == payload


def test_wrong_key_topic_or_any_changed_byte_is_unauthenticated(key):
    data = Signer(key, "/hexapod/joint_commands").sign(b"\x00\x01\x00\x00" + bytes(100))
    for bad_key, topic in ((os.urandom(32), "/hexapod/joint_commands"),
                           (key, "/hexapod/joint_states")):
        with pytest.raises(Rejected, match="unauthenticated"):
            Verifier(bad_key, topic).verify(data)
    for i in range(len(data)):
        tampered = bytearray(data)
        tampered[i] ^= 0x01
        with pytest.raises(Rejected, match="unauthenticated"):
            Verifier(key, "/hexapod/joint_commands").verify(bytes(tampered))
    for short in (b"", data[:TRAILER_BYTES - 1], data[:-1]):
        with pytest.raises(Rejected, match="unauthenticated"):
            Verifier(key, "/hexapod/joint_commands").verify(short)


def test_a_replayed_message_is_rejected_and_senders_are_kept_apart(key):
    """Every authentic message is accepted once: a replayed copy that overtakes the original
    in a reader's queue (seen in the rogue graph test: the recorder then lost the genuine
    commands queued behind it) costs nothing; any second copy, and anything older than the
    replay window, is refused."""
    from hexapod_common.core.msg_auth import REPLAY_WINDOW

    a, b = Signer(key, "/t"), Signer(key, "/t")
    v = Verifier(key, "/t")
    m1, m2 = a.sign(b"one"), a.sign(b"two")
    n1 = b.sign(b"other sender")
    assert v.verify(m2) == b"two"
    assert v.verify(m1) == b"one"           # older but never seen: the original, late
    for old in (m2, m1):
        with pytest.raises(Rejected, match="replayed"):
            v.verify(old)
    assert v.verify(n1) == b"other sender"  # a second publisher has its own sequence
    a.seq += REPLAY_WINDOW
    newest = a.sign(b"far ahead")
    assert v.verify(newest) == b"far ahead"
    a.seq = 2
    with pytest.raises(Rejected, match="replayed"):  # authentic, but beyond the window
        v.verify(a.sign(b"three, too late"))


def test_messages_that_never_arrived_are_counted_per_sender(key):
    """The holes in each sender's sequence numbers between the first and the newest message
    accepted are the messages lost on the way (a late one fills its hole); those before a
    sender's first one (a reader that matched late) and refused copies do not count."""
    a, b = Signer(key, "/t"), Signer(key, "/t")
    v = Verifier(key, "/t")
    sent = [a.sign(f"a{i}".encode()) for i in range(10)]
    late_joiner = [b.sign(f"b{i}".encode()) for i in range(5)]
    assert v.missing() == 0
    for k in (3, 4, 7, 9):  # the first three were sent before this reader matched
        v.verify(sent[k])
    assert v.missing() == 3  # 5, 6, 8
    v.verify(sent[6])  # one of them after all, late
    assert v.missing() == 2
    with pytest.raises(Rejected):
        v.verify(sent[6])  # a copy fills nothing
    assert v.missing() == 2
    v.verify(late_joiner[4])
    assert v.missing() == 2  # a sender's first message opens its span
    v.verify(late_joiner[2])  # an older one overtaken by its first: the span starts there
    assert v.missing() == 3


def test_key_file_is_private_and_checked(tmp_path):
    path = new_key_file(tmp_path)
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    assert stat.S_IMODE(path.parent.stat().st_mode) == 0o700
    key = read_key_file(path)
    assert len(key) == 32
    assert run_key({"HEXAPOD_KEY_FILE": str(path)}) == key
    assert run_key({"HEXAPOD_AUTH": "off"}) is None
    with pytest.raises(AuthError, match="no run key: set HEXAPOD_KEY_FILE"):
        run_key({})
    with pytest.raises(AuthError, match="allowed 'on' or 'off'"):
        run_key({"HEXAPOD_AUTH": "maybe", "HEXAPOD_KEY_FILE": str(path)})
    path.chmod(0o644)
    with pytest.raises(AuthError, match="mode 0600"):
        read_key_file(path)
    path.chmod(0o600)
    path.write_text("abcd\n")
    with pytest.raises(AuthError, match="2 bytes, expected 32"):
        read_key_file(path)
    with pytest.raises(AuthError, match="cannot read it"):
        read_key_file(tmp_path / "missing")


def test_drop_counter_reports_per_topic_and_cause():
    c = M.DropCounter()
    assert c.summary() == "no message dropped" and c.values() == {"dropped": "0"}
    c.add("/a", M.UNAUTHENTICATED)
    c.add("/a", M.UNAUTHENTICATED)
    assert c.add("/b", M.NON_FINITE) == 1
    assert c.total == 3 and c.by_topic("/a") == 2
    assert c.summary() == ("dropped 3 messages: /a 2 unauthenticated, /b 1 non-finite values")
    assert c.values()["dropped /a (unauthenticated)"] == "2"


def test_stamp_checks():
    assert M.check_stamp(3_000_000, 1_000_000) == 3
    for bad in (-1, 3_000_500):
        with pytest.raises(M.Dropped) as e:
            M.check_stamp(bad, 1_000_000)
        assert e.value.cause == M.BAD_STAMP
    w = M.StampWindow(ahead_s=1.0, increasing=True)
    w.check(10**8)  # no time yet: within ahead_s of 0 ...
    with pytest.raises(M.Dropped, match="ahead of the run"):
        w.check(10**15)
    w.advance(5 * 10**9)  # the first time-source stamp anchors
    w.advance(5 * 10**9 + 1_000_000)
    for bad in (5 * 10**9, 7 * 10**9, -1):  # not after, too far ahead, negative
        with pytest.raises(M.Dropped, match="stamp"):
            w.advance(bad)
    w.check(4 * 10**9)
    with pytest.raises(M.Dropped, match="ahead of the run"):
        w.check(10**15)
    now = [0.0]
    starved = M.StampWindow(ahead_s=1.0, increasing=True, rate=10.0, clock=lambda: now[0])
    starved.advance(5 * 10**9)
    now[0] = 2.0  # 2 wall s without a state: the run went on, up to 1 + 20 s ahead is fine
    starved.advance(9 * 10**9)
    with pytest.raises(M.Dropped, match="ahead of the run"):
        starved.advance(10**15)
    back = M.StampWindow()
    back.advance(9 * 10**9)
    back.advance(1_000_000)  # may go back (a new run), newest stays the maximum
    assert back.newest == 9 * 10**9


def test_finite_check():
    M.check_finite([np.zeros(3), np.ones(2)])
    for bad in (np.nan, np.inf, -np.inf):
        with pytest.raises(M.Dropped) as e:
            M.check_finite([np.zeros(3), np.array([0.0, bad])])
        assert e.value.cause == M.NON_FINITE


def test_guard_decoding_of_malformed_joint_states():
    pytest.importorskip("rclpy", reason="the guard lives on the node side (scripts/setup.sh)")
    from hexapod_common.runtime import conversions as C
    from hexapod_common.core import topics as T
    from hexapod_common.runtime.input_guard import _decode

    codec = C.CODECS[T.JOINT_COMMANDS]
    good = codec.encode(5_000_000, "pd_pf", np.zeros(12), np.zeros(12), np.ones(12))
    assert _decode(codec, good).stamp_ns == 5_000_000
    cases = {b"": M.UNDECODABLE, good[:3]: M.UNDECODABLE, good[:40]: M.UNDECODABLE,
             b"\x01\x00" + good[2:]: M.UNDECODABLE,  # big-endian encapsulation
             good[:12] + b"\xff\xff\xff\x7f" + good[16:]: M.UNDECODABLE,
             C.CODECS[T.FOOT_FORCES].encode(0, "", np.zeros(12), np.zeros(12), np.zeros(12)):
                 M.WRONG_SHAPE,
             good[:8] + (2_000_000_000).to_bytes(4, "little") + good[12:]: M.BAD_STAMP}
    rng = np.random.default_rng(3)
    for _ in range(300):
        n = int(rng.integers(0, len(good)))
        cases[good[:n]] = None  # truncated anywhere: undecodable or wrong shape
        cases[bytes(rng.integers(0, 256, int(rng.integers(0, 700)), dtype=np.uint8))] = None
    for data, cause in cases.items():
        if data == good:
            continue
        with pytest.raises(M.Dropped) as e:
            _decode(codec, data)
        assert cause is None or e.value.cause == cause, (data[:20], e.value)


def test_switch_channel_round_trip_and_unsafe_directory(tmp_path, monkeypatch):
    import threading

    from hexapod_common.core.switch_channel import (ChannelError, SwitchServer, request,
                                                    runtime_dir)

    import tempfile

    # a short directory: a UNIX socket's path has at most 107 bytes (tmp_path may be longer)
    short = tempfile.mkdtemp(prefix="hx")
    monkeypatch.setenv("XDG_RUNTIME_DIR", short)
    assert request("switch pd_p", 99, 1.0) is None  # no sim listens: the ROS path is used
    server = SwitchServer.open(99)
    assert stat.S_IMODE(runtime_dir().stat().st_mode) == 0o700
    with pytest.raises(ChannelError, match="held by another sim"):
        SwitchServer.open(99)
    answers: list[str | None] = []
    client = threading.Thread(target=lambda: answers.append(request("switch pd_p", 99, 5.0)))
    client.start()
    got: list[tuple[str, str]] = []
    end = time.monotonic() + 10
    while not got and time.monotonic() < end:
        got = server.poll()
        time.sleep(0.001)
    assert got, answers  # the client's request came (else its error is in answers)
    assert got[0][0] == "switch pd_p"
    server.reply(got[0][1], "ok switching pd_pf -> pd_p at the next tick")
    client.join(5)
    assert answers == ["ok switching pd_pf -> pd_p at the next tick"]
    with pytest.raises(ChannelError, match="did not answer within 0.2 s"):
        request("switch pd_p", 99, 0.2)
    server.close()
    stale = SwitchServer.open(99)  # a socket left behind by a dead sim is replaced
    stale.sock.close()
    SwitchServer.open(99).close()
    runtime_dir().chmod(0o755)
    with pytest.raises(ChannelError, match="mode 0700"):
        SwitchServer.open(99)
    import shutil

    shutil.rmtree(short, ignore_errors=True)


class _Lines:
    """A logger that keeps what it is given (the guard's log calls)."""

    def __init__(self) -> None:
        self.lines: list[str] = []

    def warning(self, message: str) -> None:
        self.lines.append(message)

    info = error = debug = warning


def test_forged_replayed_moved_and_garbage_messages_are_counted_and_never_decoded(
        tmp_path, monkeypatch):
    """The rejection path reads the trailer only: whatever fails authentication (or was seen
    before) is dropped and counted per cause, and the guard's decode counter does not move;
    its log grows by one line per power of ten of each (topic, cause)."""
    rclpy = pytest.importorskip("rclpy", reason="the guard lives on the node side")
    from rclpy.context import Context

    from hexapod_common.core import topics as T
    from hexapod_common.core.msg_auth import AUTH_ENV, KEY_ENV
    from hexapod_common.runtime import conversions as C
    from hexapod_common.runtime.input_guard import InputGuard

    path = new_key_file(tmp_path)
    monkeypatch.setenv(KEY_ENV, str(path))
    monkeypatch.setenv(AUTH_ENV, "on")
    key = read_key_file(path)
    ctx = Context()
    rclpy.init(context=ctx, domain_id=int(os.environ.get("ROS_DOMAIN_ID", "0") or 0) % 100 + 101)
    try:
        node = rclpy.create_node("guard_reject_test", context=ctx,
                                 start_parameter_services=False)
        log = _Lines()
        guard = InputGuard(node, log)
        period = 1_000_000
        z = np.zeros(12)

        def state(stamp: int, value: float = 0.0) -> bytes:
            return C.CODECS[T.JOINT_STATES].encode(stamp, "pd_pf", z + value, z, z)

        genuine = Signer(key, T.JOINT_STATES)
        first = genuine.sign(state(period))
        assert guard.joint_state(T.JOINT_STATES, first, period) is not None
        assert guard.decoded == 1
        forces = Signer(key, T.FOOT_FORCES).sign(
            C.CODECS[T.FOOT_FORCES].encode(period, "", z, z, z))
        tampered = bytearray(genuine.sign(state(2 * period)))
        tampered[40] ^= 0x01
        same_seq = bytearray(first)
        same_seq[40] ^= 0x01  # an accepted message's trailer on other content
        cases = [
            (first, M.REPLAYED),                                         # replayed copy
            (Signer(os.urandom(32), T.JOINT_STATES).sign(state(3 * period)),
             M.UNAUTHENTICATED),                                         # forged: other key
            (forces, M.UNAUTHENTICATED),                                 # moved to a topic
            (bytes(tampered), M.UNAUTHENTICATED),                        # altered in transit
            (bytes(same_seq), M.UNAUTHENTICATED),                        # reuses a sequence
            (state(4 * period), M.UNAUTHENTICATED),                      # no trailer at all
            (b"", M.UNAUTHENTICATED), (b"\x00\x01\x00\x00", M.UNAUTHENTICATED),
            (os.urandom(600), M.UNAUTHENTICATED),                        # garbage
        ]
        for data, cause in cases:
            before = guard.drops.counts.get((T.JOINT_STATES, cause), 0)
            assert guard.joint_state(T.JOINT_STATES, data, period) is None
            assert guard.drops.counts[(T.JOINT_STATES, cause)] == before + 1, data[:16]
        assert guard.decoded == 1  # not one of them was decoded
        assert guard.drops.total == len(cases)
        # a flood: 1000 forged messages more, still never decoded, and logged sparingly
        forger = Signer(os.urandom(32), T.JOINT_STATES)
        lines = len(log.lines)
        for k in range(1000):
            assert guard.joint_state(T.JOINT_STATES, forger.sign(state(k * period)),
                                     period) is None
        assert guard.decoded == 1
        assert guard.drops.counts[(T.JOINT_STATES, M.UNAUTHENTICATED)] == len(cases) - 1 + 1000
        # 1007 drops of one cause: lines at 10, 100 and 1000 only
        assert len(log.lines) - lines == 3, log.lines[lines:]
        # the genuine sender's next message still goes through
        assert guard.joint_state(T.JOINT_STATES, genuine.sign(state(5 * period)),
                                 period) is not None
        assert guard.decoded == 2
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)


def test_an_endpoint_whose_node_is_not_known_yet_is_named_later_by_its_name(tmp_path,
                                                                          monkeypatch):
    """rmw lists a publisher whose node it has not discovered yet as
    _NODE_NAMESPACE_UNKNOWN_/_NODE_NAME_UNKNOWN_ (the graph's answer is replaced here by
    that: it cannot be made on demand); the guard names no such phantom, and names the
    publisher once its node is known, at its next look."""
    rclpy = pytest.importorskip("rclpy", reason="the guard lives on the node side")
    from types import SimpleNamespace

    from rclpy.context import Context

    from hexapod_common.core import topics as T
    from hexapod_common.core.msg_auth import AUTH_ENV, KEY_ENV
    from hexapod_common.runtime import input_guard
    from hexapod_common.runtime.input_guard import InputGuard

    monkeypatch.setenv(KEY_ENV, str(new_key_file(tmp_path)))
    monkeypatch.setenv(AUTH_ENV, "on")
    monkeypatch.setattr(input_guard, "RELOOK", 0.0)
    ctx = Context()
    rclpy.init(context=ctx, domain_id=int(os.environ.get("ROS_DOMAIN_ID", "0") or 0) % 100 + 101)
    try:
        node = rclpy.create_node("guard_phantom_test", context=ctx,
                                 start_parameter_services=False)
        seen = [SimpleNamespace(node_name="_NODE_NAME_UNKNOWN_",
                                node_namespace="_NODE_NAMESPACE_UNKNOWN_"),
                SimpleNamespace(node_name="pd_pf_controller", node_namespace="/")]
        monkeypatch.setattr(node, "get_publishers_info_by_topic", lambda topic: list(seen))
        log = _Lines()
        guard = InputGuard(node, log)
        assert guard.joint_state(T.JOINT_COMMANDS, b"\x00\x01\x00\x00" * 8, 1_000_000) is None
        assert guard.outsiders == {} and guard.present == {}
        assert "UNKNOWN" not in guard.summary() and "UNKNOWN" not in "".join(log.lines)
        seen[0] = SimpleNamespace(node_name="_ros2cli_123", node_namespace="/")
        guard.refresh()  # the next look (no new drop): the node is known now
        assert guard.outsiders == {T.JOINT_COMMANDS: {"/_ros2cli_123"}}
        assert guard.values()["outside_publishers"] == f"{T.JOINT_COMMANDS}: /_ros2cli_123"
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)
