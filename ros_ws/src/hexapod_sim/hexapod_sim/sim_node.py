"""Node ``hexapod_sim``: integrates the model and closes the loop with the controller in charge.

Per control tick k (stamp t_k = k * control period, the same on every message of the tick):

1. publish ``/hexapod/joint_states`` (header.frame_id = the controller in charge),
   ``/hexapod/foot_forces``, ``/hexapod/hip_states`` and ``/clock``: the sample of tick k
   (engine.py's convention: state at t_k, torque T_{k-1} acting now);
2. take the command of tick k from ``/hexapod/joint_commands`` (header.stamp = t_k,
   header.frame_id = the controller in charge; others are ignored), saturate it
   (actuator.saturate) and integrate one period holding it.

This is exactly :func:`hexapod_control.core.closed_loop.run` split across processes, with
the same compiled functions in the same order; float64 travels through CDR unchanged, so
a lockstep run reproduces the in-process numbers.

Modes (parameter ``sim.mode``):

* ``lockstep`` (default): tick k+1 is published as soon as the command of tick k has been
  applied (in the command's callback; no executor in between, see hot_loop.py). Without
  a command within ``sim.lockstep_timeout`` wall seconds the tick counts as *missed*: the
  last torque is held and the controller counts as silent. While silent, ticks wait one
  control period each (real-time pacing, not the full timeout); after ``sim.hold_time``
  simulated seconds of missed ticks the sim falls back to joint damping
  T = -sim.fallback_damping * dtheta (saturated). The first valid command ends both.
* ``realtime``: ticks are paced by the wall clock (tick k published at t0 + k * period; tick
  0 waits for its command as in lockstep and starts the clock). A command that arrives in
  its period is applied at once and the next tick is integrated and serialized ahead, to
  go out on time; at the end of a period without its command (*missed*) the newest
  command of the controller in charge is applied (one that arrived after its period counts
  as *late*), else the torque is held. Silence and fallback as in lockstep.

Switching: setting ``run.controller`` (standard parameter service, e.g. ``hexapod switch``)
takes effect at the next tick boundary: the next state message names the new controller,
which answers it (its subscriptions hold the recent reference and foot forces), so no tick
is lost; the switch is published on ``/hexapod/active_controller`` (transient-local) and
logged with its tick, and ticks missed within the next 3 are counted apart. Ground and
actuator parameters change live at the next tick boundary.

Status: ``/hexapod/status`` (diagnostic_msgs/DiagnosticArray, every 0.5 s of wall time):
mode, simulated time and tick, controller in charge, missed / late / on-time ticks,
fallback on/off, switches, real-time factor, and the round trip state -> command.

A switch can also be scripted: parameters ``switch_at`` (simulated s) and ``switch_to``
make the sim set its own ``run.controller`` at that tick (scripts/run_graph.sh uses it).
Every change of ``run.controller`` (a scripted switch, ``hexapod switch``, any parameter
client) goes through the same check: the target controller node must be in the graph,
active (subscribed to the joint states: an inactive controller is not) and matched with
the sim, else the change is refused with that reason.

``summary_path`` (read-only, '' = none): at exit the sim writes its summary there as JSON
(ticks, missed / late ticks, fallback episodes, switches, and the tick ranges whose
torque was not a command of the controller in charge: held or damping fallback), for the
launcher's exit code and labels.

Start: tick 0 is published once the nodes named in ``wait_for`` show their endpoints in
the graph and the sim's publishers and subscription are matched with them (at most
``startup_timeout`` s, then it starts anyway and says what is missing); the expected
controllers are asked their lifecycle state (a warning if one is not active). Stop: at
``run.duration`` if ``stop_at_end`` (after publishing the last sample), or on
SIGINT/SIGTERM; a summary line is logged either way. Divergence of the model is logged
as an error and ends the process with exit code 1.
"""
from __future__ import annotations

import os
import sys
import time
from typing import Any

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.clock import Clock, ClockType
from rclpy.duration import Duration
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from . import conversions as C
from .core import topics as T
from .core.actuator import saturate
from .core.engine import Physics
from .core.errors import DivergenceError, HexapodError, ParameterError
from .core import msg_checks as M
from .core.layout import O_THV, P_TMAX
from .core.msg_auth import AuthError
from .core.params import N_LEGS, HexapodParams, check_controller
from .core.switch_channel import ChannelError, SwitchServer
from .core import trace as _trace
from .hot_loop import FastLogger, HotLoop, init_rclpy, install_stop_signals
from .param_topic import ParamAnnouncer
from .input_guard import InputGuard
from .ros_params import ParamBinding, declare_node_param, declare_params

#: Endpoints each node of the graph shows once it is ready to run (subscriptions, publications).
EXPECTED_ENDPOINTS: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    "trajectory_generator": ((T.JOINT_STATES,), (T.REFERENCE,)),
    "pd_p_controller": ((T.JOINT_STATES, T.FOOT_FORCES, T.REFERENCE), (T.JOINT_COMMANDS,)),
    "pd_pf_controller": ((T.JOINT_STATES, T.FOOT_FORCES, T.REFERENCE), (T.JOINT_COMMANDS,)),
    "metrics": ((T.JOINT_STATES, T.FOOT_FORCES, T.HIP_STATES, T.REFERENCE,
                 T.JOINT_COMMANDS, T.ACTIVE_CONTROLLER, T.STATUS), ()),
    # the markers node draws every state from t = 0: tick 0 waits for its subscriptions too
    "markers": ((T.JOINT_STATES, T.FOOT_FORCES, T.HIP_STATES), ()),
}
DEFAULT_WAIT_FOR = "trajectory_generator,pd_p_controller,pd_pf_controller,metrics"
STATUS_PERIOD = 0.5  # wall s between /hexapod/status messages
RESYNC_TICKS = 20    # realtime: re-anchor the schedule when this many periods behind
SWITCH_WINDOW = 3    # ticks after a switch whose misses count as caused by it
LATENCY_BIN = 20e-6  # s: histogram of state -> command round trips, bins of 20 us ...
LATENCY_BINS = 2500  # ... up to 50 ms (the last bin collects the rest)


class SimNode(Node):
    """The simulator: physics, tick publishing, command intake, modes, switch, fallback."""

    def __init__(self) -> None:
        super().__init__("hexapod_sim")
        self.log = FastLogger(self.get_logger().name)
        self.guard = InputGuard(self, self.log)  # authenticates and checks every input
        self.binding = ParamBinding(self, declare_params(self), self._on_params,
                                    check=self._check_change)
        self.stop_at_end = declare_node_param(
            self, "stop_at_end", False, "stop (and exit) after the tick at run.duration")
        wait_for = declare_node_param(
            self, "wait_for", DEFAULT_WAIT_FOR,
            "comma-separated nodes whose endpoints must be matched before tick 0 ('' = none)")
        self.wait_for = [n.strip() for n in wait_for.split(",") if n.strip()]
        self.startup_timeout = declare_node_param(
            self, "startup_timeout", 60.0, "wall s to wait for wait_for, then start anyway")
        # A scripted switch (scripts/run_graph.sh): at the first tick at or after switch_at
        # (sim s), the sim sets its own run.controller to switch_to, exactly as a
        # `hexapod switch` would; deterministic, so the run can be reproduced.
        self.switch_at = declare_node_param(self, "switch_at", -1.0,
                                            "simulated s of a scripted switch")
        self.switch_to = declare_node_param(self, "switch_to", "",
                                            "controller of the scripted switch ('' = none)")
        if self.switch_to:
            check_controller(self.switch_to)
        end = self.params.run.duration if self.stop_at_end else float("inf")
        if self.switch_to and not (0.0 <= self.switch_at <= end):
            raise ParameterError("switch_at", self.switch_at,
                                 f"a time in [0, run.duration = {end:g}] s")
        self.summary_path = declare_node_param(
            self, "summary_path", "", "write the end summary as JSON to this file ('' = no)")
        p = self.params
        self.mode = p.sim.mode
        self.period = p.sim.control_period
        self.period_ns = int(round(self.period * 1e9))
        self.end_tick = int(round(p.run.duration / self.period))
        self.physics = Physics(p)
        self._warm_up()

        self.loop = HotLoop(self)
        self.codecs = C.CODECS
        self.pub = {t: self.create_publisher(q.msg_type, t, q.publisher())
                    for t, q in C.TOPIC_QOS.items()
                    if t in (T.CLOCK, T.JOINT_STATES, T.FOOT_FORCES, T.HIP_STATES, T.STATUS,
                             T.ACTIVE_CONTROLLER)}
        self.signers = {t: self.guard.signer(t) for t in self.pub if t != T.CLOCK}
        self.cmd_sub = self.loop.subscribe(
            JointState, T.JOINT_COMMANDS, self._on_command,
            # As deep as the writers' histories: a process flooding the topic (its messages are
            # dropped) must not push the controller's command out of the queue while the sim
            # is off the CPU (that costs a lockstep timeout).
            C.TOPIC_QOS[T.JOINT_COMMANDS].subscriber(C.HISTORY_DEPTH))
        # `hexapod switch` asks here first (core/switch_channel.py): no ROS context per call.
        self.channel: SwitchServer | None = None
        try:
            self.channel = SwitchServer.open(os.environ.get("ROS_DOMAIN_ID", "0"))
        except (ChannelError, OSError) as err:
            self.log.warning(f"no local switch channel ({err}); `hexapod switch` uses the "
                             f"ROS parameter service instead")
        self.state_clients: dict[str, Any] = {}
        self.state_checks: list[tuple[str, str, Any]] = []  # (controller, reply to, future)
        self.steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(STATUS_PERIOD, self._publish_status, clock=self.steady)

        self.in_charge = p.run.controller
        self.pending_controller: str | None = None
        self.pending_params: HexapodParams | None = None
        self.torque = np.zeros((N_LEGS, 2))
        self.obs = self.physics.observe()
        self.stamp = -1
        self.prepared: tuple[int, int, list] = (0, 0, [])
        self.answered = False
        self.advanced = False  # realtime: the current tick's command applied, next tick ready
        self.newest: np.ndarray | None = None  # realtime: newest command not yet applied
        self.newest_stamp = -1  # its stamp (an older late command never replaces it)
        self.started = False
        self.finished = False
        self.missed = self.late = self.on_time = self.foreign = self.resyncs = 0
        self.silent_ticks = 0
        # Never log per tick. Lockstep warns at the first timeout; realtime after 10 ms
        # without any command.
        self.warn_after = 1 if self.mode == "lockstep" else max(1, round(0.01 / self.period))
        self.warned = False
        self.fallback = False
        self.fallback_episodes = 0
        self.switches = 0
        self.switch_tick = -SWITCH_WINDOW
        self.missed_after_switch = 0
        self.t0 = 0.0
        self.wall_start = 0.0
        self._rtf = (time.monotonic(), 0)
        self.rtf = 0.0
        self.published_at = 0.0  # wall time (monotonic) the current tick went out
        self.latency = np.zeros(LATENCY_BINS, dtype=np.int64)
        # Start values now; changes at the tick boundary that applies them (_step).
        self.announcer = ParamAnnouncer(self, self.period, deferred=True)
        # Tick ranges [a, b) whose torque was not the command of the controller in charge.
        self.not_commanded: list[list[int]] = []
        self.fallback_ranges: list[list[int]] = []
        self.switch_log: list[dict[str, object]] = []

    # ------------------------------------------------------------------ helpers
    @property
    def params(self) -> HexapodParams:
        """The node's current (validated) parameters."""
        return self.binding.params

    def _warm_up(self) -> None:
        """Run the compiled functions once so tick 0 does not pay for loading them."""
        probe = Physics(self.params)
        probe.observe()
        out = np.empty((N_LEGS, 2))
        saturate(np.zeros((N_LEGS, 2)), 1.0, out)
        probe.advance_tick(out)

    def _check_change(self, changes: list[Parameter]) -> str | None:
        """Refuse a ``run.controller`` change to a controller that cannot take over now."""
        for p in changes:
            if p.name == "run.controller" and isinstance(p.value, str) and \
                    p.value in ("pd_p", "pd_pf") and p.value != self.in_charge:
                why = self.controller_unready(p.value)
                if why:
                    return f"run.controller = {p.value!r} refused: {why}"
        return None

    def controller_unready(self, controller: str) -> str:
        """Why ``controller`` cannot take over at the next tick ('' if it can)."""
        node = f"{controller}_controller"
        domain = os.environ.get("ROS_DOMAIN_ID", "0")
        if node not in self.get_node_names():
            return f"{node} is not running on ROS_DOMAIN_ID={domain}"
        if not any(i.node_name == node for i in
                   self.get_subscriptions_info_by_topic(T.JOINT_STATES)):
            return (f"{node} is not active (no subscription to {T.JOINT_STATES}): activate "
                    f"it first (hexapod switch {controller} does)")
        if not any(i.node_name == node for i in
                   self.get_publishers_info_by_topic(T.JOINT_COMMANDS)):
            return f"{node} does not publish {T.JOINT_COMMANDS}"
        if (self.pub[T.JOINT_STATES].get_subscription_count()
                < self.count_subscribers(T.JOINT_STATES)):
            return f"{node}'s subscription to {T.JOINT_STATES} is not matched yet: try again"
        return ""

    def _mark(self, ranges: list[list[int]], k: int) -> None:
        """Add tick ``k`` to a list of [a, b) ranges (merged; at most 10000 kept)."""
        if ranges and ranges[-1][1] == k:
            ranges[-1][1] = k + 1
        elif len(ranges) < 10000:
            ranges.append([k, k + 1])

    def _on_params(self, p: HexapodParams, names: set[str]) -> None:
        if "run.controller" in names and p.run.controller != self.in_charge:
            self.pending_controller = p.run.controller
            self.log.info(f"switch to {p.run.controller} requested: takes effect at "
                          f"the next tick boundary")
        if any(n.startswith(("ground.", "actuator.")) for n in names):
            self.pending_params = p

    # ------------------------------------------------------------------ start
    def graph_missing(self) -> list[str]:
        """What is still missing before tick 0 may be published (empty when ready)."""
        missing = []
        for node in self.wait_for:
            subs, pubs = EXPECTED_ENDPOINTS.get(node, ((), ()))
            if node not in self.get_node_names():
                missing.append(f"node {node}")
                continue
            for topic in subs:
                infos = self.get_subscriptions_info_by_topic(topic)
                if not any(i.node_name == node and (
                        topic != T.CLOCK or i.qos_profile.reliability
                        == ReliabilityPolicy.RELIABLE) for i in infos):
                    missing.append(f"{node} subscribing to {topic}")
            for topic in pubs:
                if not any(i.node_name == node for i in self.get_publishers_info_by_topic(topic)):
                    missing.append(f"{node} publishing {topic}")
        for topic, pub in self.pub.items():
            if pub.get_subscription_count() < self.count_subscribers(topic):
                missing.append(f"matching of {topic}")
        if self.cmd_sub.get_publisher_count() < self.count_publishers(T.JOINT_COMMANDS):
            missing.append(f"matching of {T.JOINT_COMMANDS}")
        return missing

    def _check_controllers(self) -> None:
        """Ask each expected controller its lifecycle state (and say if it is not active).

        This also makes the first exchange between the two processes (slower: shared memory
        is mapped) happen before tick 0 rather than at the first tick after a switch.
        """
        from lifecycle_msgs.srv import GetState

        names = [n for n in self.wait_for if n.endswith("_controller")]
        clients = [self.create_client(GetState, f"/{n}/get_state") for n in names]
        self.loop.refresh()
        futures = [c.call_async(GetState.Request()) for c in clients]
        self.loop.spin(until=lambda: all(f.done() for f in futures), timeout=5.0)
        for name, client, future in zip(names, clients, futures):
            state = future.result().current_state.label if future.done() else "not answering"
            if state != "active":
                self.log.warning(f"{name} is {state}: it answers only once active")
            self.destroy_client(client)
        self.loop.refresh()

    def start(self) -> None:
        """Announce the controller in charge and publish tick 0 (after the graph is ready)."""
        self._announce()
        if self.wait_for:
            self.log.info(f"waiting for {', '.join(self.wait_for)} "
                          f"(at most {self.startup_timeout:g} s)")
            ready = self.loop.spin(until=lambda: not self.graph_missing(),
                                   timeout=self.startup_timeout)
            if self.loop.stopped:
                return
            if not ready:
                self.log.error(
                    f"starting without: {'; '.join(self.graph_missing())} (not there after "
                    f"{self.startup_timeout:g} s: check that those nodes run on this "
                    f"ROS_DOMAIN_ID)")
            self._check_controllers()
            if self.loop.stopped:
                return
        self.log.info(
            f"{self.mode} mode, {1 / self.period:g} Hz control, {self.in_charge} in charge, "
            f"run.duration {self.params.run.duration:g} s"
            + (" (stops there)" if self.stop_at_end else " (runs until stopped)"))
        self.started = True
        self.wall_start = self.t0 = time.monotonic()
        self._rtf = (self.wall_start, 0)
        self._prepare()
        self._send()

    def _announce(self) -> None:
        """Publish the controller in charge on /hexapod/active_controller (signed)."""
        self.pub[T.ACTIVE_CONTROLLER].publish(self.guard.signed(
            self.signers[T.ACTIVE_CONTROLLER], String(data=self.in_charge)))

    # ------------------------------------------------------------------ ticks
    def _prepare(self) -> None:
        """Sample the current tick and serialize its messages (not sent yet)."""
        if _trace.TRACER is not None:
            _trace.TRACER.mark(_trace.PREP0)
        k = self.physics.tick
        self.obs = obs = self.physics.observe()
        stamp = T.stamp_ns(k * self.period)
        cs = self.codecs
        out = []
        # Foot forces first: the controller needs them with the joint states that wake it.
        for topic, frame in ((T.FOOT_FORCES, ""), (T.JOINT_STATES, self.in_charge),
                             (T.HIP_STATES, "")):
            c = T.state_columns(obs, topic)
            out.append((self.pub[topic], self.signers[topic].sign(
                cs[topic].encode(stamp, frame, c.position, c.velocity, c.effort))))
        # rosgraph_msgs/Clock is a bounded type: Fast DDS refuses a sample longer than 12
        # bytes, so /clock carries no tag. No node of the graph acts on it (the trajectory
        # generator follows the authenticated states; the recorder writes /clock from them).
        out.append((self.pub[T.CLOCK], C.encode_clock(stamp)))
        self.prepared = (k, stamp, out)

    def _send(self) -> None:
        """Publish the prepared tick and arm the deadline of its command."""
        k, stamp, out = self.prepared
        self.stamp = stamp
        self.answered = False
        self.advanced = False
        self.published_at = time.monotonic()  # the round trip counts from here
        tr = _trace.TRACER
        if tr is not None:
            tr.mark(_trace.PUB0, stamp=stamp)
        for pub, data in out:
            pub.publish(data)
            if tr is not None:
                tr.mark(_trace.PUB1, pub.topic_name, stamp)
        if self.channel is not None:  # while the controllers work: off the round trip
            self._serve_channel()  # (a switch asked for now applies at the next boundary)
        now = time.monotonic()
        if self.stop_at_end and k >= self.end_tick:
            self.finished = True
            self.loop.set_deadline(None)
            self.loop.stop()
        elif self.mode == "lockstep":
            wait = self.period if self.silent_ticks else self.params.sim.lockstep_timeout
            self.loop.set_deadline(now + wait, self._on_timeout)
        elif k == 0:
            # Realtime: tick 0 waits like lockstep (the first messages of every connection
            # are slow); the wall-clock schedule starts when its command arrives.
            self.loop.set_deadline(now + self.params.sim.lockstep_timeout, self._on_period_end)
        else:
            due = self.t0 + (k + 1) * self.period
            if now - due > RESYNC_TICKS * self.period:
                self.resyncs += 1
                self.t0 = now - k * self.period
                due = now + self.period
            self.loop.set_deadline(due, self._on_period_end)

    def _on_command(self, data: bytes) -> None:
        if self.finished:
            return
        cmd = self.guard.joint_state(T.JOINT_COMMANDS, data, self.period_ns)
        if cmd is None:  # dropped (and counted) by the guard
            return
        if cmd.stamp_ns > max(self.stamp, 0):
            self.guard.drop(T.JOINT_COMMANDS, M.BAD_STAMP,
                            f"stamp {cmd.stamp_ns * 1e-9:.9g} s is ahead of the current tick")
            return
        if cmd.frame_id != self.in_charge:
            self.foreign += 1
            return
        if cmd.stamp_ns != self.stamp or self.answered or not self.started:
            if cmd.stamp_ns < self.stamp:
                self.late += 1
                if (self.mode == "realtime" and not self.advanced
                        and cmd.stamp_ns > self.newest_stamp):
                    self.newest = cmd.effort.reshape(N_LEGS, 2).copy()
                    self.newest_stamp = cmd.stamp_ns
            return
        self.answered = True
        lat = int((time.monotonic() - self.published_at) / LATENCY_BIN)
        self.latency[min(lat, LATENCY_BINS - 1)] += 1
        demand = cmd.effort.reshape(N_LEGS, 2)
        if self.silent_ticks:
            self._controller_back()
        if self.mode == "lockstep":
            self._step(demand)
            self._send()
            return
        # Realtime: integrate and serialize the next tick now, send it when its time comes.
        self.on_time += 1
        self.newest = None
        self.newest_stamp = cmd.stamp_ns
        self._step(demand)
        self.advanced = True
        if self.physics.tick == 1:  # the schedule starts: tick 1 goes out now
            self.t0 = time.monotonic() - self.period
            self.loop.set_deadline(0.0, self._on_period_end)

    def _miss(self) -> None:
        self.missed += 1
        if self.physics.tick - self.switch_tick < SWITCH_WINDOW:
            self.missed_after_switch += 1

    def _on_timeout(self) -> None:
        """Lockstep: no command for the current tick in time."""
        self._miss()
        self._count_silent()
        self._step(None)
        self._send()

    def _on_period_end(self) -> None:
        """Realtime: the period of the current tick is over; send the next tick, having
        applied the newest command (held torque or fallback if there is none)."""
        if not self.advanced:
            if self.physics.tick == 0:
                self.t0 = time.monotonic() - self.period
            self._miss()
            demand, self.newest = self.newest, None
            if demand is None:
                self._count_silent()
            elif self.silent_ticks:
                self._controller_back()
            self._step(demand)
        self._send()

    def _count_silent(self) -> None:
        """One more period without any command: hold, then fall back after sim.hold_time."""
        self.silent_ticks += 1
        k = self.physics.tick
        if self.silent_ticks == self.warn_after:
            self.warned = True
            self.log.warning(
                f"no command from {self.in_charge} since tick {k - self.silent_ticks + 1} "
                f"(t = {(k - self.silent_ticks + 1) * self.period:.3f} s): holding the last "
                f"torque")
        hold = self.params.sim.hold_time
        if not self.fallback and self.silent_ticks * self.period >= hold - 1e-12:
            self.fallback = True
            self.fallback_episodes += 1
            self.log.error(
                f"{self.in_charge} silent for {self.silent_ticks} ticks ({hold:g} s): falling "
                f"back to joint damping ({self.params.sim.fallback_damping:g} N m s/rad) "
                f"from tick {k}")

    def _controller_back(self) -> None:
        if self.warned:
            self.log.info(
                f"{self.in_charge} answers again at tick {self.physics.tick} after "
                f"{self.silent_ticks} silent ticks"
                + ("; leaving the damping fallback" if self.fallback else ""))
        self.silent_ticks = 0
        self.warned = False
        self.fallback = False

    def _step(self, demand: np.ndarray | None) -> None:
        """Apply a command (None: hold the torque, or damp in fallback), integrate one period,
        apply what changes at the tick boundary, prepare the next tick's messages."""
        P = self.physics.P
        if demand is None and self.started:
            self._mark(self.not_commanded, self.physics.tick)
            if self.fallback:
                self._mark(self.fallback_ranges, self.physics.tick)
        if demand is not None:
            saturate(demand, P[P_TMAX], self.torque)
        elif self.fallback:
            damping = -self.params.sim.fallback_damping * self.obs[O_THV]
            saturate(damping, P[P_TMAX], self.torque)
        # else: hold self.torque, the torque applied over the last period
        tr = _trace.TRACER
        if tr is not None:
            tr.mark(_trace.STEP0, stamp=self.stamp)
        self.physics.advance_tick(self.torque)
        if tr is not None:
            tr.mark(_trace.STEP1, stamp=self.stamp)
        if self.switch_to and self.physics.tick * self.period >= self.switch_at - 1e-12:
            to, self.switch_to = self.switch_to, ""
            result = self.set_parameters([Parameter("run.controller", value=to)])[0]
            if not result.successful:
                self.log.error(f"scripted switch to {to!r} refused: {result.reason}")
        if self.pending_params is not None:
            self.physics.set_params(self.pending_params)
            self.pending_params = None
        if self.pending_controller is not None:
            old, self.in_charge = self.in_charge, self.pending_controller
            self.pending_controller = None
            self.switches += 1
            self.switch_tick = self.physics.tick
            self.silent_ticks = 0
            self.warned = self.fallback = False
            k = self.physics.tick
            self.log.info(f"switched {old} -> {self.in_charge} at tick {k} "
                          f"(t = {k * self.period:.3f} s)")
            self.switch_log.append({"tick": k, "from": old, "to": self.in_charge})
            self._announce()
        self.announcer.flush(self.physics.tick)
        self._prepare()

    # ------------------------------------------------------------------ local switch channel
    def _serve_channel(self) -> None:
        """Take `hexapod switch` requests (at a tick boundary): check the target controller's
        lifecycle state, then set run.controller as a ROS client would."""
        assert self.channel is not None
        if self.state_checks:
            done = [c for c in self.state_checks if c[2].done()]
            self.state_checks = [c for c in self.state_checks if not c[2].done()]
            for to, addr, future in done:
                self._switch_checked(to, addr, future)
        for text, addr in self.channel.poll():
            parts = text.split()
            if len(parts) != 2 or parts[0] != "switch":
                self.channel.reply(addr, f"error unknown request {text[:60]!r} "
                                         f"(expected 'switch pd_p|pd_pf')")
                continue
            to = parts[1]
            try:
                check_controller(to)
            except ParameterError as err:
                self.channel.reply(addr, f"error {err}")
                continue
            if to == self.in_charge and self.pending_controller is None:
                self.channel.reply(addr, f"ok {to} already in charge")
                continue
            self._ask_state(to, addr)

    def _ask_state(self, to: str, addr: str) -> None:
        from lifecycle_msgs.srv import GetState

        name = f"{to}_controller"
        client = self.state_clients.get(name)
        if client is None:
            client = self.state_clients[name] = self.create_client(GetState,
                                                                   f"/{name}/get_state")
            self.loop.refresh()
        if not client.service_is_ready():
            assert self.channel is not None
            self.channel.reply(addr, f"error controller node {name} is not running on "
                                     f"ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID', '0')} "
                                     f"(no /{name}/get_state): start it first")
            return
        self.state_checks.append((to, addr, client.call_async(GetState.Request())))

    def _switch_checked(self, to: str, addr: str, future: Any) -> None:
        assert self.channel is not None
        res = future.result()
        state = res.current_state.label if res is not None else "not answering"
        if state != "active":
            self.channel.reply(addr, f"error {to}_controller is {state}: not active")
            return
        old = self.in_charge
        result = self.set_parameters([Parameter("run.controller", value=to)])[0]
        if not result.successful:
            self.channel.reply(addr, f"error hexapod_sim refused run.controller = {to}: "
                                     f"{result.reason}")
            return
        self.log.info(f"switch to {to} requested through the local switch channel")
        self.channel.reply(addr, f"ok switching {old} -> {to} at the next tick")

    # ------------------------------------------------------------------ status
    def status(self) -> C.Status:
        """The sim's diagnostic status (also logged as the summary)."""
        now = time.monotonic()
        k = self.physics.tick
        last_wall, last_tick = self._rtf
        if now - last_wall > 1e-3:
            self.rtf = (k - last_tick) * self.period / (now - last_wall)
        self._rtf = (now, k)
        if not self.started:
            level, msg = "warn", "waiting for the graph"
        elif self.fallback:
            level, msg = "error", f"{self.in_charge} silent: joint damping fallback"
        elif self.silent_ticks:
            level, msg = "warn", f"{self.in_charge} silent: holding the last torque"
        elif self.finished:
            level, msg = "ok", "finished"
        else:
            level, msg = "ok", "running"
        if level == "ok" and (self.guard.drops.total or self.guard.key is None):
            level, msg = "warn", f"{msg}; {self.guard.drops.summary()}"
        values = {
            "mode": self.mode, "sim_time": f"{k * self.period:.6f}", "tick": str(k),
            "controller": self.in_charge, "missed_ticks": str(self.missed),
            "late_ticks": str(self.late), "on_time_ticks": str(self.on_time),
            "fallback": "on" if self.fallback else "off",
            "fallback_episodes": str(self.fallback_episodes),
            "switches": str(self.switches), "missed_after_switch": str(self.missed_after_switch),
            "real_time_factor": f"{self.rtf:.3f}",
            "resyncs": str(self.resyncs), "end_tick": str(self.end_tick),
            "round_trip_median_ms": f"{self.latency_ms(0.5):.3f}",
            "round_trip_p99_ms": f"{self.latency_ms(0.99):.3f}",
            "stop_at_end": str(self.stop_at_end).lower(),
            "foreign_commands": str(self.foreign), **self.guard.values(),
        }
        return C.Status("hexapod_sim", level, msg, values)

    def _publish_status(self) -> None:
        self.guard.refresh()
        msg: DiagnosticArray = C.diagnostic_array(self.stamp if self.stamp >= 0 else 0,
                                                  [self.status()])
        self.pub[T.STATUS].publish(self.guard.signed(self.signers[T.STATUS], msg))

    def latency_ms(self, q: float) -> float:
        """Quantile ``q`` of the state -> command round trip (ms, from the histogram)."""
        n = int(self.latency.sum())
        if n == 0:
            return float("nan")
        i = int(np.searchsorted(np.cumsum(self.latency), q * n))
        return (i + 1) * LATENCY_BIN * 1e3

    def summary(self) -> str:
        """One line: what ran, how many ticks were missed or late."""
        k = self.physics.tick
        wall = time.monotonic() - self.wall_start if self.started else 0.0
        rtf = k * self.period / wall if wall > 0 else 0.0
        return (f"stopped at tick {k} (t = {k * self.period:.3f} s) in {self.mode} mode: "
                f"{self.missed} missed, {self.late} late, {self.on_time} on time (realtime), "
                f"{self.fallback_episodes} fallback episodes, {self.switches} switches "
                f"({self.missed_after_switch} missed within {SWITCH_WINDOW} ticks after one), "
                f"{self.resyncs} resyncs; round trip median {self.latency_ms(0.5):.2f} ms, p99 "
                f"{self.latency_ms(0.99):.2f} ms; wall {wall:.2f} s, real-time factor {rtf:.3f}; "
                f"{self.foreign} commands from a controller not in charge; inputs: "
                f"{self.guard.summary()}")

    def summary_doc(self) -> dict[str, object]:
        """The end summary as a JSON-able dict (``summary_path``)."""
        k = self.physics.tick
        return {"tick": k, "end_tick": self.end_tick, "control_period": self.period,
                "mode": self.mode, "started": self.started, "finished": self.finished,
                "controller": self.in_charge, "missed": self.missed, "late": self.late,
                "on_time": self.on_time, "foreign": self.foreign,
                "fallback_episodes": self.fallback_episodes, "switches": self.switch_log,
                "missed_after_switch": self.missed_after_switch,
                "not_commanded_ticks": self.not_commanded,
                "fallback_ticks": self.fallback_ranges}

    def write_summary(self) -> None:
        """Write :meth:`summary_doc` to ``summary_path`` (atomically), if set."""
        if not self.summary_path:
            return
        import json

        tmp = f"{self.summary_path}.tmp"
        with open(tmp, "w") as f:
            json.dump(self.summary_doc(), f)
        os.replace(tmp, self.summary_path)

    def flush(self, timeout: float = 2.0) -> None:
        """Wait (at most ``timeout`` s in all) until subscribers acknowledged every message."""
        end = time.monotonic() + timeout
        for pub in self.pub.values():
            left = max(0.0, end - time.monotonic())
            pub.wait_for_all_acked(Duration(nanoseconds=int(left * 1e9)))


def main(args: list[str] | None = None) -> int:
    """Entry point of ``hexapod_sim``."""
    if not init_rclpy(args, "hexapod_sim"):
        return 2
    node = None
    code = 0
    try:
        node = SimNode()
        install_stop_signals(node.loop)
        node.start()
        node.loop.spin()
    except (ParameterError, AuthError) as err:
        rclpy.logging.get_logger("hexapod_sim").error(str(err))
        code = 2
    except DivergenceError as err:
        if node is not None:
            node.log.error(f"{err}: stopping")
        code = 1
    except HexapodError as err:
        rclpy.logging.get_logger("hexapod_sim").error(str(err))
        code = 1
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            if node.started:
                node.log.info(node.summary())
                node._publish_status()
            try:
                node.write_summary()
            except OSError as err:
                node.log.error(f"cannot write the summary to {node.summary_path}: {err}")
            node.flush()
            if node.channel is not None:
                node.channel.close()
            node.loop.destroy()
            node.destroy_node()
        rclpy.try_shutdown()
    return code


if __name__ == "__main__":
    sys.exit(main())
