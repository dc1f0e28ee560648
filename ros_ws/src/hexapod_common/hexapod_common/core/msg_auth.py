"""Message authentication of the graph: a per-run secret and a tag on every message.

The wheels' Fast DDS has no security plugins, and rclpy 7.1.6 cannot tell a subscriber who
sent a message, so the graph authenticates its own traffic. Every message a graph node
publishes on a contract topic is padded with zeros to a multiple of 8 bytes (Fast DDS pads
samples to 4 bytes on the way) and ends with a 32-byte trailer::

    sender (8 random bytes per publisher) | sequence (uint64 LE: bits 0-55 the number, from
    1; bits 56-63 the padding) | tag (16 bytes)

with tag = keyed BLAKE2b-128(key, topic NUL payload padding sender sequence). A subscriber of the
graph accepts a message only if the tag is right (so it comes from a process holding the
run's key and was not altered, nor moved to another topic) and its sequence was not seen
before from that sender (within REPLAY_WINDOW of the newest, so a recorded message cannot be
replayed, yet a replayed copy that overtakes the original does not cost the messages behind
it). The trailer sits
after the CDR payload: ROS tools that deserialize the message (``ros2 topic echo``) ignore
it; the recorder strips it, so bags hold plain CDR.

The key: 32 random bytes per run, hex in a file readable by its owner only (mode 0600) in a
private directory (mode 0700, unpredictable name), named by ``HEXAPOD_KEY_FILE`` in the
environment of the graph's processes (scripts/run_graph.sh and ``GraphProcesses`` create
it). ``HEXAPOD_AUTH=off`` runs without authentication (said in the log and the status).
ROS-free.
"""
from __future__ import annotations

import hashlib
import os
import secrets
import stat
import struct
import tempfile
from pathlib import Path
from typing import Mapping

from hexapod_common.core import trace
from .errors import HexapodError

KEY_ENV = "HEXAPOD_KEY_FILE"
AUTH_ENV = "HEXAPOD_AUTH"
KEY_BYTES = 32
SENDER_BYTES = 8
TAG_BYTES = 16
TRAILER_BYTES = SENDER_BYTES + 8 + TAG_BYTES  # 32: keeps 8-byte alignment
MAX_SENDERS = 256  # senders remembered per topic (a restarted node is a new sender)
_SEQ = struct.Struct("<Q")
_SEQ_MASK = (1 << 56) - 1
_ZEROS = bytes(8)


class AuthError(HexapodError):
    """The run's key is missing, unreadable or not private."""


class Rejected(Exception):
    """A message failed authentication; ``cause`` is 'unauthenticated' or 'replayed'."""

    def __init__(self, cause: str) -> None:
        super().__init__(cause)
        self.cause = cause


def new_key_file(parent: str | os.PathLike[str] | None = None) -> Path:
    """Create a fresh run key: ``<private dir>/key`` (dir 0700, file 0600); its path."""
    d = Path(tempfile.mkdtemp(prefix="hexapod_key_", dir=parent))  # mode 0700
    path = d / "key"
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(secrets.token_hex(KEY_BYTES) + "\n")
    return path


def read_key_file(path: str | os.PathLike[str]) -> bytes:
    """The key in ``path``; AuthError unless it is ours, private and 32 bytes of hex."""
    p = Path(path)
    try:
        st = p.stat()
        text = p.read_text().strip()
    except OSError as err:
        raise AuthError(f"run key file {p}: cannot read it ({err.strerror})") from err
    if not stat.S_ISREG(st.st_mode):
        raise AuthError(f"run key file {p}: not a regular file")
    if st.st_uid != os.getuid() or st.st_mode & 0o077:
        raise AuthError(f"run key file {p}: must belong to this user with mode 0600 "
                        f"(found uid {st.st_uid}, mode {stat.S_IMODE(st.st_mode):04o})")
    try:
        key = bytes.fromhex(text)
    except ValueError as err:
        raise AuthError(f"run key file {p}: not hex") from err
    if len(key) != KEY_BYTES:
        raise AuthError(f"run key file {p}: {len(key)} bytes, expected {KEY_BYTES}")
    return key


def run_key(env: Mapping[str, str] | None = None) -> bytes | None:
    """The run's key from the environment; None if ``HEXAPOD_AUTH=off``; AuthError if none."""
    env = os.environ if env is None else env
    mode = env.get(AUTH_ENV, "on").lower()
    if mode == "off":
        return None
    if mode != "on":
        raise AuthError(f"{AUTH_ENV}={env[AUTH_ENV]!r}: allowed 'on' or 'off'")
    path = env.get(KEY_ENV, "")
    if not path:
        raise AuthError(f"no run key: set {KEY_ENV} to the graph's key file (scripts/"
                        f"run_graph.sh prints it; GraphProcesses makes one), or {AUTH_ENV}=off "
                        f"to run without message authentication")
    return read_key_file(path)


def _base(key: bytes, topic: str) -> "hashlib.blake2b":
    h = hashlib.blake2b(key=key, digest_size=TAG_BYTES)
    h.update(topic.encode() + b"\0")
    return h


class Signer:
    """Appends the trailer to the messages of one publisher on ``topic``."""

    def __init__(self, key: bytes, topic: str) -> None:
        self.topic = topic
        self.sender = secrets.token_bytes(SENDER_BYTES)
        self.seq = 0
        self._base = _base(key, topic)

    def sign(self, payload: bytes) -> bytes:
        """``payload`` + zero padding to 8 bytes + sender + sequence + tag."""
        tr = trace.TRACER
        if tr is not None:
            tr.mark(trace.SIGN0, self.topic, trace.header_stamp(payload))
        self.seq += 1
        n = len(payload)
        pad = _ZEROS[:-n % 8]
        head = self.sender + _SEQ.pack(self.seq | len(pad) << 56)
        h = self._base.copy()
        h.update(payload)
        h.update(pad)
        h.update(head)
        out = b"".join((payload, pad, head, h.digest()))  # the one copy of the payload
        if tr is not None:
            tr.mark(trace.SIGN1, self.topic)
        return out


def _hash(data: bytes) -> int:
    """Python's (per-process keyed) hash of a message's bytes."""
    return hash(data if type(data) is bytes else bytes(data))


class Verifier:
    """Checks and strips the trailer of the messages received on ``topic``.

    :meth:`check` reads the trailer's sender and sequence first: a sequence seen before from
    that sender is refused without hashing (a replayed copy, or a different message that
    claims an authentic message's sequence: then it cannot be authentic, since a signer
    never repeats a sequence); only a message with a new sequence pays for the tag.
    """

    def __init__(self, key: bytes, topic: str) -> None:
        self.topic = topic
        self._base = _base(key, topic)
        self.last: dict[bytes, int] = {}  # sender -> newest sequence accepted
        #: sender -> {sequence: hash(message)} of the messages accepted within REPLAY_WINDOW
        #: below the newest: a message may arrive after a newer one (a replayed copy can
        #: overtake the original in a reader's queue), so "not seen before" is the test, not
        #: "newer than the newest"; the (process-keyed) hash tells an exact copy (replayed)
        #: from another message that claims the same sequence (unauthenticated).
        self.seen: dict[bytes, dict[int, int]] = {}
        #: sender -> [first sequence accepted, messages accepted]: with ``last``, the
        #: messages of a sender that never came (:meth:`missing`)
        self.span: dict[bytes, list[int]] = {}
        self._retired_missing = 0  # missing() of senders forgotten (MAX_SENDERS)

    def missing(self) -> int:
        """Messages that never arrived between the first and the newest accepted of each
        sender: a writer's sequence numbers have no holes, so these were lost on the way
        (a reader queue that overflowed, a writer history that dropped them before this
        reader took them) or are still on the way. Those sent before the first accepted
        one (a reader that matched late) are not counted."""
        return self._retired_missing + sum(self.last[s] - first + 1 - n
                                           for s, (first, n) in self.span.items())

    def check(self, data: bytes) -> int:
        """The payload's length in ``data`` (an authentic, new message: bytes
        ``[0, length)``); raises Rejected otherwise. Nothing is copied."""
        n = len(data) - TRAILER_BYTES
        if n < 0:
            raise Rejected("unauthenticated")
        sender = data[n:n + SENDER_BYTES]
        (word,) = _SEQ.unpack_from(data, n + SENDER_BYTES)
        seq, pad = word & _SEQ_MASK, word >> 56
        if pad > 7 or pad > n or seq == 0:
            raise Rejected("unauthenticated")
        seen = self.seen.get(sender)
        if seen is not None:
            known = seen.get(seq)
            if known is not None:
                raise Rejected("replayed" if known == _hash(data) else "unauthenticated")
            newest = self.last[sender]
            if seq <= newest - REPLAY_WINDOW:
                raise Rejected("replayed")
        else:
            newest = 0
        h = self._base.copy()
        h.update(memoryview(data)[:n + SENDER_BYTES + 8])
        if not secrets.compare_digest(h.digest(), data[n + SENDER_BYTES + 8:]):
            raise Rejected("unauthenticated")
        if seen is None:
            if len(self.last) >= MAX_SENDERS:
                old = next(iter(self.last))
                first, accepted = self.span.pop(old)
                self._retired_missing += self.last.pop(old) - first + 1 - accepted
                self.seen.pop(old, None)
            seen = self.seen[sender] = {}
            self.last[sender] = 0
            self.span[sender] = [seq, 0]
        span = self.span[sender]
        span[1] += 1
        if seq < span[0]:  # an older one overtaken by the first: the span starts here
            span[0] = seq
        seen[seq] = _hash(data)
        if seq > newest:
            self.last[sender] = newest = seq
        if len(seen) > 2 * REPLAY_WINDOW:
            self.seen[sender] = {x: v for x, v in seen.items() if x > newest - REPLAY_WINDOW}
        return int(n - pad)

    def verify(self, data: bytes) -> bytes:
        """The payload of an authentic, new message (a copy); raises Rejected otherwise."""
        return data[:self.check(data)]


#: How far (in messages of one sender) an authentic message may arrive behind the newest
#: one and still be accepted once.
REPLAY_WINDOW = 65536


class Unsigned:
    """Stand-in for Signer and Verifier when authentication is off: data unchanged."""

    def __init__(self, topic: str) -> None:
        self.topic = topic

    def sign(self, payload: bytes) -> bytes:
        """``payload`` itself."""
        tr = trace.TRACER
        if tr is not None:  # the breakdown's signing segments, then of zero work
            tr.mark(trace.SIGN0, self.topic, trace.header_stamp(payload))
            tr.mark(trace.SIGN1, self.topic)
        return payload

    def check(self, data: bytes) -> int:
        """The length of ``data``: all of it is the payload."""
        return len(data)

    def verify(self, data: bytes) -> bytes:
        """``data`` itself."""
        return data


__all__ = ["AUTH_ENV", "AuthError", "KEY_ENV", "REPLAY_WINDOW", "Rejected", "Signer",
           "TRAILER_BYTES",
           "Unsigned", "Verifier", "new_key_file", "read_key_file", "run_key"]
