"""A lean spin loop for the per-tick topics of the graph's nodes.

rclpy's executors rebuild a wait set from every entity of a node (parameter and lifecycle
services, timers, ...) on every callback: about 0.3 ms of Python per message on these
machines, which alone rules out a 1 kHz lockstep loop across processes (a state -> command
-> state ping-pong between two processes ran at 1.1-2.2 ms per tick with the
SingleThreadedExecutor, 0.28-0.34 ms with this loop). So each node splits its entities:

* *hot* subscriptions (raw, serialized bytes) are created through :meth:`HotLoop.subscribe`
  in a callback group that executors never run; :meth:`HotLoop.spin` waits on them alone
  and takes every pending message as soon as it arrives. A subscription made with
  ``newest=True`` serves a node that acts on the newest sample only (a controller answers
  the newest state; the states it fell behind on are past their deadline): of the messages
  queued at a wake-up, its callback gets the newest first, then older ones until one is
  accepted (the callback returns True); the rest are *superseded*, counted per topic in
  :attr:`HotLoop.superseded`, never acted on, and given to ``superseded(data)`` (the node
  authenticates them there, so that a replayed copy of one is still refused as seen
  before). A subscription made with
  ``wake=False`` does not wake the loop: its messages wait until the node takes them
  (:meth:`HotLoop.take`), e.g. when another topic's message needs them; every wake-up
  costs CPU that the other processes of a 2-core machine are waiting for;
* the node's services (parameters, lifecycle, ...), clients and timers are in the loop's
  wait set too, and the loop serves them itself when ready: it takes the request and calls
  the service's callback, completes a client's future with its response, or calls the
  timer's callback, as rclpy's executor would, but without the
  executor's rebuilding of a wait set from every entity of the node (0.5-0.7 ms a time
  here: a `ros2 param set` or the status timer then made the realtime loop miss a tick).
  While hot messages keep the loop busy, only every :data:`OTHERS_PERIOD` (5 ms) does a wait
  include them; the waits in between are on the hot subscriptions alone: each entity in a
  wait set costs rmw_wait CPU at every wake-up, and the five nodes' main threads used
  0.79-0.93 ms of CPU per lockstep tick at 1 kHz this way against 1.03 ms with every entity
  in every wait (two pairs of ``bench_graph.py --breakdown`` runs, alternating);
* everything else (the time source and other executor-run subscriptions, events, guard
  conditions, coroutine callbacks) stays with a standard ``SingleThreadedExecutor``, run
  once every ``service_period`` (and when a coroutine callback is ready).

One optional wall-clock deadline (:meth:`HotLoop.set_deadline`) serves the sim's lockstep
timeout and real-time pacing. Everything runs in the main thread: no locks, and callbacks
never run concurrently.

Signals: :func:`install_stop_signals` makes SIGINT and SIGTERM stop the loop at its next
wake-up, so that ``main`` can close files and log a summary.

Middleware: :func:`configure_middleware` (called before ``rclpy.init``) makes Fast DDS
publish synchronously unless the environment says otherwise: rmw_fastrtps's default here
hands every message to a sender thread, which on a 2-core machine cost the lockstep graph
about a third of its speed (measured: real-time factor 0.86 asynchronous, 1.42
synchronous, same machine, minutes apart). It also installs a Fast DDS profile against
lost samples (:data:`FASTDDS_PROFILE`).
"""
from __future__ import annotations

import gc
import inspect
import os
import signal
import sys
import time
from typing import Any, Callable

from rclpy.callback_groups import CallbackGroup
from rclpy.exceptions import InvalidHandle
from rclpy.executors import SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.logging import LoggingSeverity
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.subscription import Subscription

from hexapod_common.core import trace
from .dds_profile import (FASTDDS_PROFILE, HAND_PARTICIPANT_IDS, domain_id_from_env,
                          private_profile, run_partition, unused_participant_id)

RawCallback = Callable[[bytes], Any]  # ``newest`` subscriptions: True if accepted
#: Longest single wait (s): how late a stop request (signal) may be noticed by an idle node.
MAX_WAIT = 0.1
#: Wall s between two waits that include the node's services, clients and timers while
#: hot messages keep the loop busy (the waits in between are on the hot subscriptions
#: alone). Each entity in a wait set costs rmw_wait CPU at every wake-up: a lifecycle node's
#: 13 services added ~12-20 us of CPU to each wait here (cold caches, 28 us with the
#: subscription alone), at every tick of every node; a request now waits at most this long
#: while the graph runs (an idle loop waits on everything).
OTHERS_PERIOD = 0.005


class _NeverExecuted(CallbackGroup):
    """Entities in this group are invisible to executors (the hot loop serves them)."""

    def can_execute(self, entity: Any) -> bool:
        return False

    def beginning_execution(self, entity: Any) -> bool:
        return False

    def ending_execution(self, entity: Any) -> None:
        pass


class _HotSub:
    """One hot subscription as the loop serves it: its rcl handle (and the handle's pointer,
    which the wait set reports), message type, callback, topic, the handler of superseded
    messages (``newest`` subscriptions) and whether a message wakes the loop."""

    __slots__ = ("sub", "handle", "pointer", "msg_type", "callback", "topic", "newest", "wake")

    def __init__(self, sub: Subscription, msg_type: Any, callback: RawCallback,
                 newest: RawCallback | None, wake: bool) -> None:
        self.sub = sub
        self.handle = sub.handle
        self.pointer = sub.handle.pointer
        self.msg_type = msg_type
        self.callback = callback
        self.topic = sub.topic_name
        self.newest = newest
        self.wake = wake


class HotLoop:
    """Serve raw hot subscriptions with low latency and the rest of a node through an executor.

    ``service_period`` (s): how often the executor runs for what the loop does not serve
    itself (module doc; each run costs 0.3-0.7 ms of executor overhead).
    ``batch_interval`` (s), if set, makes :meth:`spin` pause that long after each wake-up,
    so a node that needs throughput rather than latency (the recorder) takes its messages
    in batches instead of waking up for each.
    """

    def __init__(self, node: Node, service_period: float = 2.0,
                 batch_interval: float = 0.0) -> None:
        self.node = node
        self.executor = SingleThreadedExecutor(context=node.context)
        self.executor.add_node(node)
        self.service_period = float(service_period)
        self.batch_interval = float(batch_interval)
        self._group = _NeverExecuted()
        self._subs: dict[int, _HotSub] = {}  # id() of the Subscription -> its record
        #: Messages taken but never given to their callback, per topic: a newer one of a
        #: ``newest`` subscription was accepted at the same wake-up.
        self.superseded: dict[str, int] = {}
        self._wait_set: Any = None  # the hot subscriptions and the entities the loop serves
        self._hot_set: Any = None  # the hot subscriptions alone (see OTHERS_PERIOD)
        self._others_due = 0.0  # monotonic s: the next wait includes services, timers, ...
        self._waking: list[_HotSub] = []  # the subscriptions in the wait set
        self._others: tuple[list[Any], list[Any], list[Any]] = ([], [], [])
        # pointer -> service / timer the loop serves itself (module doc)
        self._services: dict[int, Any] = {}
        self._timers: dict[int, Any] = {}
        self._clients: dict[int, Any] = {}
        self._deadline: float | None = None
        self._deadline_cb: Callable[[], None] | None = None
        self._next_service = 0.0
        self.stopped = False
        self.running = False
        self._gc_frozen = False

    # ------------------------------------------------------------------ entities
    def subscribe(self, msg_type: Any, topic: str, callback: RawCallback,
                  qos: QoSProfile, wake: bool = True,
                  newest: RawCallback | None = None) -> Subscription:
        """A raw subscription whose callback receives the serialized message (bytes); with
        ``newest`` (the handler of superseded messages), served newest first (module doc)."""
        sub = self.node.create_subscription(msg_type, topic, callback, qos, raw=True,
                                            callback_group=self._group)
        self._subs[id(sub)] = _HotSub(sub, msg_type, callback, newest, wake)
        self._wait_set = None
        return sub

    def unsubscribe(self, sub: Subscription) -> None:
        """Destroy a subscription made by :meth:`subscribe`."""
        self._subs.pop(id(sub), None)
        self._wait_set = None
        self.node.destroy_subscription(sub)

    def subscriptions(self) -> list[Subscription]:
        """The hot subscriptions, in the order they were made."""
        return [e.sub for e in self._subs.values()]

    def refresh(self) -> None:
        """Rebuild the wait set (call after creating services, clients or timers)."""
        self._wait_set = None

    def set_wake(self, sub: Subscription, wake: bool) -> None:
        """Whether a message on ``sub`` wakes the loop (else it waits for :meth:`take`)."""
        entry = self._subs.get(id(sub))
        if entry is not None and wake != entry.wake:
            entry.wake = wake
            self._wait_set = None

    def take(self, sub: Subscription) -> int:
        """Take every message queued on ``sub`` now and run its callback on each (newest
        first until one is accepted, for a ``newest`` subscription); how many were taken."""
        entry = self._subs.get(id(sub))
        return 0 if entry is None else self._take(entry)

    def _take(self, entry: _HotSub) -> int:
        h, msg_type, cb, topic, newest = (entry.handle, entry.msg_type, entry.callback,
                                          entry.topic, entry.newest)
        tr = trace.TRACER
        batch: list[bytes] = []
        n = 0
        while True:
            t0 = time.time_ns() if tr is not None else 0
            taken = h.take_message(msg_type, True)
            if taken is None:
                break
            n += 1
            if tr is not None:
                tr.taken(topic, t0, taken[0], taken[1])
            if newest is not None:
                batch.append(taken[0])
            else:
                cb(taken[0])
        for i in range(len(batch) - 1, -1, -1):
            if cb(batch[i]):
                if i and newest is not None:
                    self.superseded[topic] = self.superseded.get(topic, 0) + i
                    for data in batch[:i]:
                        newest(data)
                break
        return n

    def set_deadline(self, when: float | None, callback: Callable[[], None] | None = None
                     ) -> None:
        """Call ``callback`` once at monotonic time ``when`` (None cancels); one at a time."""
        self._deadline = when
        self._deadline_cb = callback

    @property
    def deadline(self) -> float | None:
        """The pending deadline (monotonic s), if any."""
        return self._deadline

    def stop(self) -> None:
        """Make :meth:`spin` return at its next wake-up."""
        self.stopped = True

    # ------------------------------------------------------------------ spinning
    def _rebuild(self) -> None:
        node = self.node
        self._waking = [e for e in self._subs.values() if e.wake]
        self._others = ([s.handle for s in node.services], [c.handle for c in node.clients],
                        [t.handle for t in node.timers])
        self._services = {s.handle.pointer: s for s in node.services
                          if not inspect.iscoroutinefunction(s.callback)}
        self._timers = {t.handle.pointer: t for t in node.timers
                        if not inspect.iscoroutinefunction(t.callback)}
        self._clients = {c.handle.pointer: c for c in node.clients}
        self._wait_set = _rclpy.WaitSet(len(self._waking), 0, len(self._others[2]),
                                        len(self._others[1]), len(self._others[0]), 0,
                                        node.context.handle)
        self._hot_set = (_rclpy.WaitSet(len(self._waking), 0, 0, 0, 0, 0, node.context.handle)
                         if self._waking else None)
        self._others_due = 0.0

    def poll(self, timeout: float) -> None:
        """Wait up to ``timeout`` s for hot messages and run their callbacks; serve ready
        services, clients and timers (looked at every :data:`OTHERS_PERIOD` while hot
        messages keep the loop busy); run the deadline callback when due, and the executor
        every ``service_period``."""
        if self._wait_set is None:
            self._rebuild()
        waking = self._waking
        now = time.monotonic()
        if self._deadline is not None:
            timeout = min(timeout, self._deadline - now)
        timeout = min(timeout, self._next_service - now)
        others = now >= self._others_due or not waking
        if others:
            ws = self._wait_set
            ws.clear_entities()
            for e in waking:
                ws.add_subscription(e.handle)
            services, clients, timers = self._others
            for h in services:
                ws.add_service(h)
            for h in clients:
                ws.add_client(h)
            for h in timers:
                ws.add_timer(h)
        else:
            timeout = min(timeout, self._others_due - now)
            ws = self._hot_set
            ws.clear_entities()
            for e in waking:
                ws.add_subscription(e.handle)
        ws.wait(max(0, int(timeout * 1e9)))
        tr = trace.TRACER
        if tr is not None:
            tr.wake()
        ready = ws.get_ready_entities('subscription')
        if ready:
            for e in waking:
                if e.pointer in ready:
                    self._take(e)
                    if self._wait_set is None:  # a callback changed the subscriptions
                        break
        run_executor = False
        if others:
            served = False
            for kind, own, serve in (('service', self._services, _serve_request),
                                     ('client', self._clients, _take_response),
                                     ('timer', self._timers, _call_timer)):
                for ptr in ws.get_ready_entities(kind):
                    served = True
                    entity = own.get(ptr)
                    if entity is None:  # a coroutine callback: the executor's
                        run_executor = True
                    else:
                        serve(entity)
            # Woken by hot messages: the others can wait a while. Woken by one of them, or
            # by nothing: keep waiting on everything (a request may bring more).
            if ready and not served:
                self._others_due = time.monotonic() + OTHERS_PERIOD
        now = time.monotonic()
        if self._deadline is not None and now >= self._deadline:
            cb, self._deadline, self._deadline_cb = self._deadline_cb, None, None
            if cb is not None:
                cb()
        if run_executor or now >= self._next_service:
            self._next_service = now + self.service_period
            self.executor.spin_once(timeout_sec=0)

    def spin(self, until: Callable[[], bool] | None = None, timeout: float | None = None
             ) -> bool:
        """Run until :meth:`stop`, shutdown, ``until()`` or ``timeout`` s; True if ``until``
        became true (or, without ``until``, if stopped). The ``until`` condition is checked
        at every wake-up (at least every 0.1 s)."""
        end = None if timeout is None else time.monotonic() + timeout
        ctx = self.node.context
        if not self._gc_frozen:
            # Everything allocated so far (rclpy, numba, numpy: ~10^5 objects) is permanent:
            # take it out of the collector's reach so that full collections stay short.
            gc.collect()
            gc.freeze()
            self._gc_frozen = True
        self.running = True
        try:
            while ctx.ok() and not self.stopped:
                if until is not None and until():
                    return True
                left = MAX_WAIT
                if end is not None:
                    left = end - time.monotonic()
                    if left <= 0:
                        return False
                self.poll(min(left, MAX_WAIT))
                if self.batch_interval > 0:
                    time.sleep(self.batch_interval)
        finally:
            self.running = False
        return until is None

    def drain(self) -> int:
        """Take and process every message already queued on the hot subscriptions."""
        return sum(self._take(e) for e in list(self._subs.values()))

    def destroy(self) -> None:
        """Remove the node from the executor and shut the executor down."""
        self.executor.remove_node(self.node)
        self.executor.shutdown(timeout_sec=0)


def _serve_request(srv: Any) -> None:
    """Take one request of a ready service and answer it (rclpy executor's _take_service)."""
    try:
        with srv.handle:
            request, header = srv.handle.service_take_request(srv.srv_type.Request)
    except InvalidHandle:  # destroyed meanwhile
        return
    if header is None:
        return
    srv.send_response(srv.callback(request, srv.srv_type.Response()), header)


def _take_response(client: Any) -> None:
    """Take one response of a ready client and complete its request's future (rclpy
    executor's _take_client; the future's done-callbacks run at once)."""
    try:
        with client.handle:
            header, response = client.handle.take_response(client.srv_type.Response)
    except InvalidHandle:
        return
    if header is None:
        return
    try:
        future = client.get_pending_request(header.request_id.sequence_number)
    except KeyError:  # the request was cancelled
        return
    future.set_result(response)


def _call_timer(tmr: Any) -> None:
    """Call a ready timer's callback (rclpy executor's _take_timer)."""
    try:
        with tmr.handle:
            tmr.handle.call_timer()
    except InvalidHandle:
        return
    tmr.callback()


class FastLogger:
    """A node's logger without rclpy's per-call source inspection.

    ``node.get_logger().info(...)`` looks its caller up with ``inspect.getframeinfo``: about
    0.7 ms a call here, enough to make a realtime tick late. This calls the same rcutils
    function (console and /rosout alike) with the caller taken from the frame directly.
    """

    def __init__(self, name: str) -> None:
        self.name = name

    def _log(self, severity: LoggingSeverity, message: str) -> None:
        if _rclpy.rclpy_logging_logger_is_enabled_for(self.name, int(severity)):
            f = sys._getframe(2)
            _rclpy.rclpy_logging_rcutils_log(severity, self.name, message, f.f_code.co_name,
                                             f.f_code.co_filename, f.f_lineno)

    def debug(self, message: str) -> None:
        """Log at DEBUG."""
        self._log(LoggingSeverity.DEBUG, message)

    def info(self, message: str) -> None:
        """Log at INFO."""
        self._log(LoggingSeverity.INFO, message)

    def warning(self, message: str) -> None:
        """Log at WARN."""
        self._log(LoggingSeverity.WARN, message)

    def error(self, message: str) -> None:
        """Log at ERROR."""
        self._log(LoggingSeverity.ERROR, message)


def configure_middleware(participant_ids: range = HAND_PARTICIPANT_IDS) -> None:
    """DDS settings of the graph's processes; call before ``rclpy.init``.

    Publication is synchronous and, with localhost-only discovery (the project's default),
    the Fast DDS profile :data:`FASTDDS_PROFILE` applies, written to a private file of this
    process (never read from a shared, predictable path: see dds_profile.py) with the first
    participant id of ``participant_ids`` whose shared-memory ports do not exist (never a
    SIGKILLed process's: see :func:`unused_participant_id`); the environment overrides both
    (``RMW_FASTRTPS_PUBLICATION_MODE``, ``FASTRTPS_DEFAULT_PROFILES_FILE``, which the graph
    launcher sets to its own private copy).
    """
    os.environ.setdefault("RMW_FASTRTPS_PUBLICATION_MODE", "SYNCHRONOUS")
    if (os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "") == "LOCALHOST"
            and "FASTRTPS_DEFAULT_PROFILES_FILE" not in os.environ):
        participant = unused_participant_id(domain_id_from_env(), participant_ids)
        os.environ["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(private_profile(
            remove_at_exit=True, participant_id=participant, partition=run_partition()))


def init_rclpy(args: list[str] | None, node_name: str) -> bool:
    """``configure_middleware`` + ``rclpy.init`` without signal handlers (see
    :func:`install_stop_signals`); a bad command line is one line on stderr and False."""
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    configure_middleware()
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except _rclpy.RCLError as err:
        print(f"{node_name}: error: bad ROS arguments: {err}", file=sys.stderr)
        return False
    return True


def install_stop_signals(loop: HotLoop, on_stop: Callable[[int], None] | None = None) -> None:
    """SIGINT/SIGTERM stop ``loop`` at its next wake-up (or raise KeyboardInterrupt if it is
    not running yet); later signals are ignored so that the shutdown (closing a bag, say)
    completes; SIGKILL remains for a node that hangs. Call after ``rclpy.init`` with
    ``signal_handler_options=SignalHandlerOptions.NO``."""
    stopping = False

    def handler(signum: int, frame: Any) -> None:
        nonlocal stopping
        if stopping:
            return
        stopping = True
        if loop.running:
            loop.stop()
            if on_stop is not None:
                on_stop(signum)
            return
        raise KeyboardInterrupt

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)


__all__ = ["FASTDDS_PROFILE", "FastLogger", "HotLoop", "configure_middleware", "init_rclpy",
           "install_stop_signals"]
