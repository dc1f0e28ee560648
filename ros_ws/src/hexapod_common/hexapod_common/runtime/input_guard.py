"""The guard in front of every subscriber of the graph's nodes, and the signer behind every
publisher.

Each received message goes through :class:`InputGuard`: authentication (``core.msg_auth``:
the run's key, a tag and a sequence number per message), decoding, the contract's names and
sizes, the stamp (``core.msg_checks.StampWindow``) and finite values. A message that fails
is dropped, counted per topic and cause, logged (the first of each topic and cause, then at
10, 100, 1000, ... of them) and reported on ``/hexapod/status`` and in the node's end
summary. When messages without a valid tag arrive on a topic, the guard looks up who
publishes it (``get_publishers_info_by_topic``: rclpy cannot tell which publisher sent a
given message) and names the publishers that are not nodes of this graph; while any is
there it looks again every :data:`RELOOK` s, so that the status says when one has left. A
node's status warns of what is true now (:meth:`InputGuard.warn_now`): an outside publisher
present, a message dropped in the last :data:`RECENT_DROPS` s, or authentication off; the
counts and every publisher ever seen stay in the values and the end summary.
"""
from __future__ import annotations

import math
import struct
import time
from typing import Any, Callable

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.serialization import serialize_message

from hexapod_common.runtime import conversions as C
from hexapod_common.core import msg_checks as M
from hexapod_common.core import topics as T
from hexapod_common.core import trace
from ..core.msg_auth import Rejected, Signer, Unsigned, Verifier, run_key

CONTROLLER_NODES = ("pd_p_controller", "pd_pf_controller")
GRAPH_NODES = ("hexapod_sim", "trajectory_generator", *CONTROLLER_NODES, "metrics", "markers")
#: Who may publish each topic (node names; namespaces are not used by the graph).
PUBLISHERS: dict[str, tuple[str, ...]] = {
    T.CLOCK: ("hexapod_sim",), T.JOINT_STATES: ("hexapod_sim",),
    T.FOOT_FORCES: ("hexapod_sim",), T.HIP_STATES: ("hexapod_sim",),
    T.ACTIVE_CONTROLLER: ("hexapod_sim",), T.REFERENCE: ("trajectory_generator",),
    T.JOINT_COMMANDS: CONTROLLER_NODES, T.INDICES: ("metrics",), T.MARKERS: ("markers",),
    T.STATUS: GRAPH_NODES, T.PARAMETERS: (*GRAPH_NODES, "foxglove_bridge"),
    T.RECORDED: ("metrics",),
}
#: The node name rmw gives an endpoint whose node it has not discovered yet.
UNKNOWN_NODE = "_NODE_NAME_UNKNOWN_"
#: Topics whose messages the graph's nodes sign (/clock is a bounded type: no room for a tag).
SIGNED_TOPICS = frozenset(PUBLISHERS) - {T.CLOCK}
_STAMP = struct.Struct("<iI")
#: What an unauthenticated message lacks (said with the first drop of each topic).
AUTH_HINT = ("no valid 32-byte trailer (sender | sequence | BLAKE2b-128 tag keyed with the "
             "run's key from HEXAPOD_KEY_FILE): sign with hexapod_common.auth, or as "
             "docs/controllers.md, 'Authentication', says")
_U32 = struct.Struct("<I")
#: Wall s after the last dropped message during which a status still warns of drops.
RECENT_DROPS = 5.0
#: Wall s between two looks at whether the outside publishers seen are still there (each
#: look asks the graph for a suspect topic's publishers, ~0.3 ms; only while one is there).
RELOOK = 2.0


def _decode(codec: C.JointStateCodec, data: bytes, size: int | None = None
            ) -> C.JointStateView:
    """codec.decode of the first ``size`` bytes of ``data`` (default all) with every
    failure turned into Dropped (undecodable or wrong shape)."""
    if size is None:
        size = len(data)
    if size < 16 or data[:2] != C.ENCAPSULATION[:2]:
        raise M.Dropped(M.UNDECODABLE, f"{size} bytes, not little-endian CDR")
    sec, nsec = _STAMP.unpack_from(data, 4)
    if nsec >= C.NS:
        raise M.Dropped(M.BAD_STAMP, f"nanosec {nsec} >= 1e9")
    (flen,) = _U32.unpack_from(data, 12)
    if flen == 0 or 16 + flen > size:
        raise M.Dropped(M.UNDECODABLE, f"frame_id of {flen} bytes in {size}")
    try:
        return codec.decode(data, size)
    except ValueError as err:  # UnicodeDecodeError included
        cause = M.WRONG_SHAPE if "does not carry" in str(err) else M.UNDECODABLE
        raise M.Dropped(cause, str(err)) from err
    except (struct.error, IndexError, OverflowError) as err:
        raise M.Dropped(M.UNDECODABLE, str(err)) from err


class InputGuard:
    """Authenticates, checks and counts what one node receives; signs what it publishes.

    Raises :class:`~hexapod_common.core.msg_auth.AuthError` (no or bad run key) at creation.
    """

    def __init__(self, node: Node, log: Any) -> None:
        self.node = node
        self.log = log
        trace.name_process(node.get_name())
        self.key = run_key()
        self.drops = M.DropCounter()
        self.outsiders: dict[str, set[str]] = {}  # every one seen (the end summary)
        self.present: dict[str, set[str]] = {}  # those there at the last look (the status)
        self._relook_at = 0.0  # monotonic s of the next look while some are present
        self._unnamed = False  # an endpoint's node was not known at the last look
        self._drops_seen = 0  # drops.total at the last refresh
        self._last_drop = -math.inf  # monotonic s of the refresh that saw new drops
        self._verifiers: dict[str, Verifier | Unsigned] = {}
        self._suspect: set[str] = set()
        #: nodes outside GRAPH_NODES whose signed messages were accepted (a controller that
        #: joined the graph, vouched for by the sim): never named as outside the graph
        self.vouched: set[str] = set()
        self._looked_at = 0  # drops counted at the last look-up
        #: Messages that passed authentication and went on to be decoded (a rejected one
        #: never gets that far: tests/test_msg_guard.py counts on it).
        self.decoded = 0
        if self.key is None:
            log.warning("message authentication is off (HEXAPOD_AUTH=off): any process on "
                        "this ROS_DOMAIN_ID can drive the graph")

    # ------------------------------------------------------------------ publishing
    def signer(self, topic: str) -> Signer | Unsigned:
        """A signer for one publisher of ``topic`` (its own sender id)."""
        return Unsigned(topic) if self.key is None else Signer(self.key, topic)

    def signed(self, signer: Signer | Unsigned, msg: Any) -> bytes:
        """A message (typed, or serialized bytes) serialized and signed."""
        data = msg if isinstance(msg, bytes) else serialize_message(msg)
        return signer.sign(data)

    # ------------------------------------------------------------------ receiving
    def _verifier(self, topic: str) -> Verifier | Unsigned:
        v = self._verifiers.get(topic)
        if v is None:
            v = self._verifiers[topic] = (Unsigned(topic) if self.key is None
                                          else Verifier(self.key, topic))
        return v

    def missing(self) -> dict[str, int]:
        """Per topic, the authentic messages that never arrived between the first and the
        newest taken of each publisher (``Verifier.missing``: lost on the way); empty with
        authentication off (no sequence numbers to tell)."""
        out = {}
        for topic, v in self._verifiers.items():
            n = v.missing() if isinstance(v, Verifier) else 0
            if n:
                out[topic] = n
        return out

    def payload(self, topic: str, data: bytes) -> bytes | None:
        """The authenticated payload of ``data`` (trailer stripped), or None (dropped)."""
        n = self.payload_size(topic, data)
        return None if n is None else data[:n]

    def payload_size(self, topic: str, data: bytes) -> int | None:
        """The length of the authenticated payload at the start of ``data`` (an authentic,
        new message), or None (dropped and counted). Only the trailer is read before the
        verdict: a replayed message costs no hashing, a forged one one tag, and neither is
        decoded."""
        try:
            n = self._verifier(topic).check(data)
        except Rejected as r:
            self.drop(topic, r.cause, AUTH_HINT if r.cause == M.UNAUTHENTICATED else "")
            return None
        if trace.TRACER is not None:
            trace.TRACER.mark(trace.VERIFIED, topic, trace.header_stamp(data))
        return n

    def joint_state(self, topic: str, data: bytes, period_ns: int,
                    window: M.StampWindow | None = None, advance: bool = False
                    ) -> C.JointStateView | None:
        """A checked JointState of ``topic`` (None if dropped): stamped on a control tick
        (``period_ns``) and, with ``window``, in it (``advance``: the message is the node's
        time source)."""
        got = self._joint_state(topic, data, period_ns, window, advance)
        return None if got is None else got[1]

    def joint_state_payload(self, topic: str, data: bytes, period_ns: int,
                            window: M.StampWindow | None = None, advance: bool = False
                            ) -> tuple[bytes, C.JointStateView] | None:
        """(payload, view) of a checked JointState, as :meth:`joint_state`."""
        got = self._joint_state(topic, data, period_ns, window, advance)
        return None if got is None else (data[:got[0]], got[1])

    def _joint_state(self, topic: str, data: bytes, period_ns: int,
                     window: M.StampWindow | None, advance: bool
                     ) -> tuple[int, C.JointStateView] | None:
        """(payload size, view): one pass over ``data`` (trailer, then the payload in
        place, never copied)."""
        n = self.payload_size(topic, data)
        if n is None:
            return None
        view = self.authenticated_joint_state(topic, data, n, period_ns, window, advance)
        return None if view is None else (n, view)

    def authenticated_joint_state(self, topic: str, data: bytes, size: int, period_ns: int,
                                  window: M.StampWindow | None = None, advance: bool = False
                                  ) -> C.JointStateView | None:
        """A checked JointState of ``topic`` (None if dropped) from a message that
        :meth:`payload_size` accepted already (its payload: the first ``size`` bytes)."""
        n = size
        tr = trace.TRACER
        self.decoded += 1
        try:
            view = _decode(C.CODECS[topic], data, n)
            if tr is not None:
                tr.mark(trace.DECODED, topic, view.stamp_ns)
            M.check_finite((view.position, view.velocity, view.effort))
            if len(view.effort) > len(T.JOINT_NAMES) and topic == T.JOINT_COMMANDS:
                M.check_drive_gains(view.position, view.velocity, view.effort,
                                    len(T.JOINT_NAMES))
            M.check_stamp(view.stamp_ns, period_ns)
            if window is not None:
                if advance:
                    window.advance(view.stamp_ns)
                else:
                    window.check(view.stamp_ns)
        except M.Dropped as d:
            self.drop(topic, d.cause, d.detail)
            return None
        if tr is not None:
            tr.mark(trace.CHECKED, topic, view.stamp_ns)
        return view

    def string(self, topic: str, data: bytes, allowed: tuple[str, ...]
               ) -> tuple[bytes, str] | None:
        """(payload, text) of a checked std_msgs/String whose text is one of ``allowed``."""
        payload = self.payload(topic, data)
        if payload is None:
            return None
        try:
            if len(payload) < 9 or payload[:2] != C.ENCAPSULATION[:2]:
                raise M.Dropped(M.UNDECODABLE, f"{len(payload)} bytes")
            (n,) = struct.unpack_from("<I", payload, 4)
            if n == 0 or 8 + n > len(payload) or payload[7 + n] != 0:
                raise M.Dropped(M.UNDECODABLE, "string length does not fit")
            try:
                text = payload[8:7 + n].decode()
            except UnicodeDecodeError as err:
                raise M.Dropped(M.UNDECODABLE, "not UTF-8") from err
            if text not in allowed:
                raise M.Dropped(M.BAD_CONTENT, f"{text[:40]!r} is none of {', '.join(allowed)}")
        except M.Dropped as d:
            self.drop(topic, d.cause, d.detail)
            return None
        return payload, text

    # ------------------------------------------------------------------ reporting
    def drop(self, topic: str, cause: str, detail: str = "") -> None:
        """Count a dropped message; log the first of each (topic, cause), then every 10^k."""
        n = self.drops.add(topic, cause)
        if n == 1 or (n % 10 == 0 and str(n).rstrip("0") == "1"):
            what = "a message" if n == 1 else f"{n} messages so far"
            self.log.warning(f"dropped {what} on {topic}: {cause}"
                             + (f" ({detail})" if detail and n == 1 else ""))
        if cause in (M.UNAUTHENTICATED, M.REPLAYED):
            first = topic not in self._suspect
            self._suspect.add(topic)
            if first:
                self.look_up()

    def look_up(self) -> None:
        """Name the publishers of the suspect topics that are not nodes of this graph (new
        ones logged as a warning, those that left as info)."""
        self._looked_at = self.drops.total
        self._relook_at = time.monotonic() + RELOOK
        self._unnamed = False
        for topic in sorted(self._suspect):
            try:
                infos = self.node.get_publishers_info_by_topic(topic)
            except Exception:  # noqa: BLE001 - the graph can be gone at shutdown
                continue
            # an endpoint whose node's name has not been discovered yet (rmw's
            # _NODE_NAME_UNKNOWN_) is named at a later look, by its name
            names = {f"{i.node_namespace.rstrip('/')}/{i.node_name}" for i in infos
                     if i.node_name != UNKNOWN_NODE
                     and ((i.node_name not in PUBLISHERS.get(topic, ())
                           and i.node_name not in self.vouched)
                          or i.node_namespace not in ("/", ""))}
            self._unnamed |= any(i.node_name == UNKNOWN_NODE for i in infos)
            left = self.present.get(topic, set()) - names
            if names:
                self.present[topic] = names
            else:
                self.present.pop(topic, None)
            if left:
                self.log.info(f"publishers outside the graph on {topic} left: "
                              f"{', '.join(sorted(left))}")
            new = names - self.outsiders.get(topic, set())
            if new:
                self.outsiders.setdefault(topic, set()).update(new)
                self.log.warning(
                    f"publishers on {topic} that are not nodes of this graph: "
                    f"{', '.join(sorted(new))}; their messages are dropped "
                    f"({self.drops.by_topic(topic)} so far)")

    def vouch(self, node: str) -> None:
        """``node`` (in namespace /) is a node of the graph: its messages were accepted."""
        if node not in self.vouched:
            self.vouched.add(node)
            for names in self.outsiders.values():
                names.discard(f"/{node}")
            self.outsiders = {t: n for t, n in self.outsiders.items() if n}

    def refresh(self) -> None:
        """Look the suspect topics' publishers up again if more was dropped, or every
        :data:`RELOOK` s while an outside publisher is there (call at a low rate, e.g. from
        the status timer)."""
        now = time.monotonic()
        if self.drops.total != self._drops_seen:
            self._drops_seen = self.drops.total
            self._last_drop = now
        if self._suspect and (self.drops.total != self._looked_at
                              or ((self.present or self._unnamed)
                                  and now >= self._relook_at)):
            self.look_up()

    def warn_now(self) -> bool:
        """Does something call for a warning now: a publisher outside the graph present at
        the last look, a message dropped in the last :data:`RECENT_DROPS` s (as of the last
        :meth:`refresh`), or authentication off?"""
        return (self.key is None or bool(self.present)
                or time.monotonic() - self._last_drop < RECENT_DROPS)

    def now(self) -> str:
        """One phrase for a status: who is publishing from outside now, the drops (and if
        none came lately), who came and left."""
        parts = []
        if self.present:
            parts.append("publishers outside the graph: " + _names(self.present))
        if self.drops.total:
            recent = time.monotonic() - self._last_drop < RECENT_DROPS
            parts.append(self.drops.summary()
                         + ("" if recent else f" (none in the last {RECENT_DROPS:g} s)"))
        left = self._left()
        if left:
            parts.append("gone from outside the graph: " + _names(left))
        if self.key is None:
            parts.append("authentication off")
        return "; ".join(parts) or self.drops.summary()

    def _left(self) -> dict[str, set[str]]:
        """Outside publishers seen that were not there at the last look, per topic."""
        out = {t: n - self.present.get(t, set()) for t, n in self.outsiders.items()}
        return {t: n for t, n in out.items() if n}

    def values(self) -> dict[str, str]:
        """Diagnostic key/values: authentication, drops, publishers outside the graph."""
        out = {"authentication": "off" if self.key is None else "on", **self.drops.values()}
        out["outside_publishers"] = _names(self.present) or "none"  # there now
        out["outside_publishers_left"] = _names(self._left()) or "none"
        return out

    def summary(self) -> str:
        """One phrase for the end summary: drops and publishers outside the graph."""
        text = self.drops.summary()
        if self.outsiders:
            text += "; publishers outside the graph: " + _names(self.outsiders)
        if self.key is None:
            text += "; authentication off"
        return text

    def publish_status(self, name: str, stamp_ns: Any, period: float = 1.0,
                       extra: Callable[[], dict[str, str]] | None = None) -> Callable[[], None]:
        """Publish this node's status (signed) on /hexapod/status every ``period`` wall s;
        ``stamp_ns()`` gives the stamp, ``extra()`` more key/values. Returns the function
        that publishes one now (e.g. at a lifecycle transition). Call before creating the
        node's HotLoop (or refresh it after)."""
        pub = self.node.create_publisher(DiagnosticArray, T.STATUS,
                                         C.TOPIC_QOS[T.STATUS].publisher())
        signer = self.signer(T.STATUS)

        def tick() -> None:
            pub.publish(signer.sign(self.status(name, stamp_ns(),
                                                extra() if extra is not None else None)))
        self.node.create_timer(period, tick, clock=Clock(clock_type=ClockType.STEADY_TIME))
        return tick

    def status(self, name: str, stamp_ns: int, extra: dict[str, str] | None = None) -> bytes:
        """A /hexapod/status message of this node's inputs (for non-sim nodes)."""
        self.refresh()
        level = "warn" if self.warn_now() else "ok"
        return C.encode_statuses(max(0, stamp_ns), [C.Status(
            name, level, self.now(), {**self.values(), **(extra or {})})])


def _names(by_topic: dict[str, set[str]]) -> str:
    """'topic: a, b; topic2: c' ('' if none)."""
    return "; ".join(f"{t}: {', '.join(sorted(n))}" for t, n in sorted(by_topic.items()) if n)


__all__ = ["GRAPH_NODES", "InputGuard", "PUBLISHERS", "SIGNED_TOPICS"]
