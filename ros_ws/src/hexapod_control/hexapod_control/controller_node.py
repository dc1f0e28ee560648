"""Lifecycle nodes ``pd_p_controller``, ``pd_pf_controller`` and one per registered plug-in.

PD-P and PD-P&F run their compiled law (PD-P&F with ``pd_pf.force_loop: drive`` sends
24-entry drive commands); a registered plug-in (``hexapod controllers``, e.g. ``pd_alpha``)
runs in a node named as the controller, its ``law`` called per tick through
``controller_api.call_law`` as the engine's closed loop calls it, on the same observation:
a plug-in's node also takes ``/hexapod/hip_states`` (the hip rows; the sim publishes them
after the states of the tick, so a plug-in waits for them as for a late input).

Lifecycle: *configure* reads the gains (``pd_p.*`` or ``pd_pf.*``; they may also change
while running), creates the command publisher and subscribes to the reference and the foot
forces; *activate* enables the publisher and subscribes to the joint states (the last
endpoint to appear, which tells the sim this controller is ready); *deactivate* stops
answering and drops the joint-state subscription (so the graph shows that it cannot take
over: the sim refuses a switch to it); *cleanup* removes everything. With ``autostart``
(default true) the node configures and activates itself at start, so no lifecycle manager
is needed; the lifecycle services keep working (``hexapod switch`` uses them).

Per tick: a ``/hexapod/joint_states`` message whose header.frame_id names this controller
(``hexapod_common.core.labels.in_charge``) is answered once the reference and the foot forces
with the same stamp are there (both architectures wait for the same set, so
their timing is the same): the demanded torque
T_C = :func:`hexapod_control.core.controllers.control_law` of that sample, exactly as
:func:`hexapod_control.core.closed_loop.run_ticks` computes it, published on
``/hexapod/joint_commands`` with header.stamp = the state's stamp and frame_id = the
architecture's name. References and foot forces queue in their subscriptions without
waking the node (the last ``conversions.CONTROL_DEPTH`` of each) and are taken at every state, so a
controller that is not in charge costs one wake-up per tick and is ready to take over at
any tick boundary. Every input goes through the guard (``hexapod_common.runtime.input_guard``) and
every command is signed with the run's key.

A controller that is not in charge is not woken by the states: it takes its queued states,
foot forces and references every ``IDLE_DRAIN`` s (checking only the inputs from the newest
state's tick on), and is woken at once by ``/hexapod/active_controller`` when the sim names
it (the sim announces a switch right after the switch tick's states, so the state that names
it is then queued, or comes next and wakes it). An idle controller woken by every state cost
1.2-1.4 s of CPU per 5 s lockstep run at 1 kHz, the graph's third-largest share
(docs/benchmarks.md, S4).
Every state of ours is answered, in order, late rather than never (answering only the
newest state was tried: at the same share of on-time ticks it left ticks unanswered at
switches). Every input is authenticated on arrival (a forged or replayed one is dropped
and counted without being decoded); inputs of ticks before every state still to answer are
not needed: they are skipped undecoded and counted (``skipped_inputs`` in the status and
the end summary).
"""
from __future__ import annotations

import sys
import time
from typing import Any

import numpy as np
from hexapod_common.core import msg_checks as M
from hexapod_common.core import topics as T
from hexapod_common.core import trace as _trace
from hexapod_common.core.trace import header_stamp
from hexapod_common.core.labels import in_charge
from hexapod_common.core.params import N_LEGS, HexapodParams
from hexapod_common.runtime.hot_loop import FastLogger, HotLoop
from hexapod_common.runtime.input_guard import InputGuard
from hexapod_common.runtime.node_main import run_node
from hexapod_common.runtime.param_topic import ParamAnnouncer
from hexapod_common.runtime.ros_params import ParamBinding, declare_node_param, declare_params
from hexapod_common.runtime.rt_sched import refresh_once, use_rt_priority
from rclpy.duration import Duration
from rclpy.lifecycle import LifecycleState, TransitionCallbackReturn
from rclpy.lifecycle import Node as LifecycleNode
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from hexapod_common.runtime import conversions as C
from hexapod_common.runtime import inputs_matched

from hexapod_common.core import cdr
from hexapod_common.core.controller_names import node_of
from hexapod_common.core.errors import CdrError, ParameterError
from hexapod_common.core.layout import C_KD, C_KF, C_KP, C_TFF, COMMAND_SHAPE
from hexapod_common.core.params import CONTROLLERS, controller_group

from .core import registry
from .core.controller_api import call_law
from .core.controllers import (PD_P, control_law, controller_code, gain_vector,
                               pd_pf_drive_command)
from .core.waits import InputWaits

MAX_BUFFERED = 10000  # stamps kept per buffered topic at most
#: Stamps of unchecked inputs kept per topic while not in charge (beyond them, or for a second
#: sample of a stamp, an input is checked on arrival as when in charge).
MAX_UNCHECKED = 1000
IDLE_DRAIN = 0.005  # s between two takes of the queued inputs while not in charge
WARN_EVERY = 5.0  # wall s between two warnings about late inputs (the counts go on)
WARN_AFTER = 10  # waits before the first warning (tick 0 always waits for the first reference)


class ControllerNode(LifecycleNode):
    """A joint controller of one architecture ('pd_p' or 'pd_pf')."""

    def __init__(self, architecture: str) -> None:
        self.arch = architecture
        # A registered plug-in (not pd_p / pd_pf): its Python law through call_law, the
        # engine's per-tick loop; the node is named as the controller (node_of).
        self.plugin = architecture not in CONTROLLERS
        self.code = PD_P if self.plugin else controller_code(architecture)
        self.ctrl: Any = None
        super().__init__(node_of(architecture))
        self.log = FastLogger(self.get_logger().name)
        self.guard = InputGuard(self, self.log)
        # The states are this node's time source: strictly increasing, at most
        # msg_checks.AHEAD_S ahead of the last; references and forces within AHEAD_S of it.
        self.window = M.StampWindow(increasing=True)
        self.binding = ParamBinding(self, declare_params(self), self._on_params)
        self.autostart = declare_node_param(self, "autostart")
        # SCHED_FIFO for the control path when asked (the launcher does in realtime mode),
        # at rt_priority whether in charge or not: with the idle controller one priority
        # below (the design until 2026-12) it was starved on a loaded machine and lost the
        # ticks after a switch to it more often (docs/benchmarks.md, sixth stop).
        self.rt = use_rt_priority(self, self.log)
        self.rt_refreshed = False
        # Every lifecycle transition (ours or a ROS tool's) is logged and sent at once on
        # /hexapod/status, so the bag records it with the sim time it happened at.
        self.lifecycle = "unconfigured"
        self.status_now = self.guard.publish_status(
            self.get_name(), lambda: self.window.newest or 0,
            extra=lambda: {"lifecycle": self.lifecycle,
                           "skipped_inputs": str(self.skipped_inputs),
                           "waited_reference": str(self.waits.reference),
                           "waited_forces": str(self.waits.forces),
                           "given_up": str(self.waits.given_up),
                           "in_charge": str(self.in_charge).lower()})
        self.cmd_signer = self.guard.signer(T.JOINT_COMMANDS)
        self.loop = HotLoop(self)
        # asked before tick 0; the command writer's matched readers counted (inputs_matched)
        inputs_matched.offer(self, self.loop.subscriptions, self.guard,
                             lambda: () if self.pub is None else (self.pub,))
        self.js_codec = C.CODECS[T.JOINT_STATES]
        self.ff_codec = C.CODECS[T.FOOT_FORCES]
        self.ref_codec = C.CODECS[T.REFERENCE]
        self.cmd_codec = C.CODECS[T.JOINT_COMMANDS]
        self.pub: Any = None
        self.subs: dict[str, Any] = {}
        self.active = False
        self.in_charge = False  # named by the newest state
        self.named = False  # named by the newest /hexapod/active_controller
        self.refs: dict[int, C.JointStateView] = {}
        self.forces: dict[int, C.JointStateView] = {}
        self.hips: dict[int, C.JointStateView] = {}  # a plug-in's only
        # The inputs a state waits for besides itself: (topic, its buffer by stamp)
        self.inputs: tuple[tuple[str, dict[int, C.JointStateView]], ...] = (
            (T.REFERENCE, self.refs), (T.FOOT_FORCES, self.forces)) + (
            ((T.HIP_STATES, self.hips),) if self.plugin else ())
        # Inputs taken while not in charge, authenticated but not decoded yet: stamp -> the
        # serialized sample and its payload's size (see _on_input).
        self.unchecked: dict[str, dict[int, tuple[bytes, int]]] = {t: {} for t, _ in
                                                                   self.inputs}
        # States of ours waiting for their reference or foot forces (answered, in order, as
        # soon as those are there, also after newer states: late beats never in realtime).
        self.pending: dict[int, C.JointStateView] = {}
        self.obs = np.zeros((9, N_LEGS, 2))
        self.theta_d = np.zeros((N_LEGS, 2))
        self.theta_vel_d = np.zeros((N_LEGS, 2))
        self.demand = np.zeros((N_LEGS, 2))
        self.cmd = np.zeros(COMMAND_SHAPE)
        self.drive = False
        self.answered = 0
        self.waits = InputWaits()  # states whose reference or foot forces came after them
        self.warned_at = -WARN_EVERY  # monotonic s of the last warning about late inputs
        self.skipped_inputs = 0  # references and foot forces of ticks before the newest state
        self.input_floor = -1  # inputs of ticks before it are not needed (no state to answer)
        self._load_gains(self.binding.params)
        self.period_ns = int(round(self.binding.params.sim.control_period * 1e9))
        if not self.plugin:
            self._law()  # warm up the compiled law before the first tick
        self.last_state = -1  # stamp of the newest state of ours (ns)
        self.announcer = ParamAnnouncer(self, self.binding.params.sim.control_period,
                                        self._next_tick)

    def _next_tick(self) -> int:
        """The first tick answered with a parameter changed now: the oldest state waiting
        for its inputs, else the tick after the newest state seen (an idle controller's
        too: it takes its queued states first, so the tick is the graph's, not the one it
        last answered)."""
        period_ns = T.stamp_ns(self.binding.params.sim.control_period)
        states = self.subs.get(T.JOINT_STATES)
        if not self.in_charge and states is not None:
            self.loop.take(states)
        if self.pending:  # states waiting for their inputs: the oldest is answered next
            return C.tick_of(min(self.pending), period_ns)
        newest = max(self.last_state, -1 if self.window.newest is None else self.window.newest)
        return C.tick_of(newest, period_ns) + 1 if newest >= 0 else 0

    # ------------------------------------------------------------------ parameters
    def _load_gains(self, p: HexapodParams) -> None:
        g = p.gains(self.arch)
        self.period = p.sim.control_period
        if self.plugin:  # a fresh, reset instance (as the engine's when parameters change)
            self.ctrl = registry.create(self.arch, p)
            self.gains = np.zeros(5)
            self.drive = False
            self.described = repr(g)
            return
        self.gains = gain_vector(g)
        self.described = (f"gains (Kp1, Kd1, Kp2, Kd2, K_f) = "
                          f"{tuple(float(x) for x in self.gains)}")
        # PD-P&F with its force loop in the drive: the command carries the drive's gains
        self.drive = str(getattr(g, "force_loop", "topic")) == "drive"
        self.l1, self.l2 = p.robot.leg_length_1, p.robot.leg_length_2

    def _on_params(self, p: HexapodParams, names: set[str]) -> None:
        if any(n.startswith(controller_group(self.arch) + ".") for n in names):
            self._load_gains(p)

    # ------------------------------------------------------------------ lifecycle
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Read the gains, create the command publisher, subscribe to reference and forces."""
        self._load_gains(self.binding.params)
        self.pub = self.create_lifecycle_publisher(
            JointState, T.JOINT_COMMANDS, C.TOPIC_QOS[T.JOINT_COMMANDS].publisher())
        self.subs[T.REFERENCE] = self.loop.subscribe(
            JointState, T.REFERENCE, self._on_reference,
            C.TOPIC_QOS[T.REFERENCE].subscriber(C.CONTROL_DEPTH), wake=False)
        self.subs[T.FOOT_FORCES] = self.loop.subscribe(
            JointState, T.FOOT_FORCES, self._on_forces,
            C.TOPIC_QOS[T.FOOT_FORCES].subscriber(C.CONTROL_DEPTH), wake=False)
        if self.plugin:  # the hip rows of a plug-in's observation, as the engine's
            self.subs[T.HIP_STATES] = self.loop.subscribe(
                JointState, T.HIP_STATES, self._on_hips,
                C.TOPIC_QOS[T.HIP_STATES].subscriber(C.CONTROL_DEPTH), wake=False)
        self.log.info(f"configured: {self.described}"
                      + ("; force loop in the drive (24-entry drive commands)"
                         if self.drive else ""))
        self._entered("inactive")
        return TransitionCallbackReturn.SUCCESS

    def _entered(self, label: str) -> None:
        self.lifecycle = label
        self.status_now()

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Enable the publisher and listen to the joint states."""
        ret = super().on_activate(state)
        if T.JOINT_STATES not in self.subs:
            self.subs[T.JOINT_STATES] = self.loop.subscribe(
                JointState, T.JOINT_STATES, self._on_state,
                C.TOPIC_QOS[T.JOINT_STATES].subscriber(C.CONTROL_DEPTH))
            self.subs[T.ACTIVE_CONTROLLER] = self.loop.subscribe(
                String, T.ACTIVE_CONTROLLER, self._on_active,
                C.TOPIC_QOS[T.ACTIVE_CONTROLLER].subscriber(1))
        self.active = True
        self.log.info("active: answering the states that name "
                      f"'{self.arch}' as the controller in charge")
        self._entered("active")
        return ret

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop answering; reference and forces keep filling their buffers."""
        self.active = False
        self.pending.clear()
        for topic in (T.JOINT_STATES, T.ACTIVE_CONTROLLER):
            sub = self.subs.pop(topic, None)
            if sub is not None:
                self.loop.unsubscribe(sub)
        self.named = False
        self.log.info("inactive")
        self._entered("inactive")
        return super().on_deactivate(state)

    def _teardown(self) -> None:
        self.active = False
        self.pending.clear()
        for sub in self.subs.values():
            self.loop.unsubscribe(sub)
        self.subs.clear()
        if self.pub is not None:
            self.destroy_lifecycle_publisher(self.pub)
            self.pub = None
        for _, buf in self.inputs:
            buf.clear()
        for held in self.unchecked.values():
            held.clear()

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Remove publisher and subscriptions."""
        self._teardown()
        self.log.info("unconfigured")
        self._entered("unconfigured")
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Remove publisher and subscriptions."""
        self._teardown()
        self.log.info("finalized")
        self._entered("finalized")
        return TransitionCallbackReturn.SUCCESS

    def _drain(self) -> None:
        """Not in charge: take the queued states, then the queued references and foot
        forces, kept unchecked (those of ticks before the newest state are skipped, also
        among those kept); again in IDLE_DRAIN s while states come, else the next state
        wakes the loop."""
        states = self.subs.get(T.JOINT_STATES)
        if states is not None:
            took = self.loop.take(states)
            if self.in_charge:  # a state named us: _on_state answered it
                return
            if not took:  # no states flow (the run ended or has not begun): let one wake us
                self.loop.set_wake(states, True)
            elif self.loop.deadline is None:
                self.loop.set_deadline(time.monotonic() + IDLE_DRAIN, self._drain)
        for topic, _ in self.inputs:
            sub = self.subs.get(topic)
            if sub is not None:
                self.loop.take(sub)
            held = self.unchecked[topic]
            for s in [s for s in held if 0 <= s < self.input_floor]:
                del held[s]
                self.skipped_inputs += 1

    # ------------------------------------------------------------------ per tick
    def _on_input(self, topic: str, buf: dict[int, Any], data: bytes) -> None:
        """A reference or foot-force sample: authenticated on arrival (a forged or replayed
        one is dropped and counted, never decoded), then buffered by stamp (the newest
        MAX_BUFFERED); one of a tick before the newest state is not needed, and not decoded.

        Not in charge, a sample is kept undecoded (by its stamp, one per stamp,
        MAX_UNCHECKED stamps at most) and decoded and checked only once a state of ours
        needs it (:meth:`_check_unchecked`): checking the ~5 ms of inputs an idle drain takes
        cost 0.2-0.5 ms, and a state that named this controller while a drain ran waited for
        it (the switch tick's command came late at 20 of 50 switches at 1 kHz,
        docs/benchmarks.md)."""
        n = self.guard.payload_size(topic, data)
        if n is None:
            return
        stamp = header_stamp(data)
        if 0 <= stamp < self.input_floor:
            self.skipped_inputs += 1
            return
        if not self.in_charge:
            held = self.unchecked[topic]
            if stamp not in held and len(held) < MAX_UNCHECKED:
                held[stamp] = (data, n)
                return
        self._check_input(topic, buf, data, n)

    def _check_unchecked(self, stamp: int | None = None) -> None:
        """Check the inputs kept unchecked: those of tick ``stamp`` (ns), or all (None;
        those of ticks before the newest state are skipped unchecked, as on arrival)."""
        for topic, buf in self.inputs:
            held = self.unchecked[topic]
            if stamp is not None:
                got = held.pop(stamp, None)
                if got is not None:
                    self._check_input(topic, buf, *got)
                continue
            if not held:
                continue
            items = sorted(held.items())
            held.clear()
            for s, got in items:
                if 0 <= s < self.input_floor:
                    self.skipped_inputs += 1
                else:
                    self._check_input(topic, buf, *got)

    def _check_input(self, topic: str, buf: dict[int, Any], data: bytes, size: int) -> None:
        """Decode and check one authenticated input (the guard) and buffer it by stamp."""
        msg = self.guard.authenticated_joint_state(topic, data, size, self.period_ns,
                                                   self.window)
        if msg is None:
            return
        buf[msg.stamp_ns] = msg
        if len(buf) > MAX_BUFFERED:
            del buf[min(buf)]
        if msg.stamp_ns in self.pending:
            self._answer()

    def _on_reference(self, data: bytes) -> None:
        self._on_input(T.REFERENCE, self.refs, data)

    def _on_forces(self, data: bytes) -> None:
        self._on_input(T.FOOT_FORCES, self.forces, data)

    def _on_hips(self, data: bytes) -> None:
        self._on_input(T.HIP_STATES, self.hips, data)

    def _on_active(self, data: bytes) -> None:
        """``/hexapod/active_controller`` (the sim's, authenticated): named, this controller
        lets the states wake it again and takes those queued (one may name it already)."""
        payload = self.guard.payload(T.ACTIVE_CONTROLLER, data)
        if payload is None:
            return
        try:
            name = cdr.decode_string(payload)
        except CdrError as err:
            self.guard.drop(T.ACTIVE_CONTROLLER, M.UNDECODABLE, str(err))
            return
        self.named = name == self.arch
        states = self.subs.get(T.JOINT_STATES)
        if self.named and states is not None:
            self.loop.set_wake(states, True)
            self.loop.take(states)

    def _on_state(self, data: bytes) -> None:
        """A state: ours to answer if it names this controller (and we are active).

        Reference and foot forces do not wake the loop (hot_loop.py): they queue in their
        subscriptions (``conversions.CONTROL_DEPTH`` deep) and are taken here at every state
        that names this controller, and every IDLE_DRAIN s while another one is in charge:
        so the queues hold at most a few ms of inputs when a state names this controller (a
        switch then costs little more than any tick). Only if an input is still missing
        does it wake the loop until it is there.
        """
        js = self.guard.joint_state(T.JOINT_STATES, data, self.period_ns, self.window,
                                    advance=True)
        if js is None:
            return
        if not self.rt_refreshed:  # every peer matched by now: late receive threads too
            refresh_once(self)
        stamp = js.stamp_ns
        self.input_floor = min(self.pending, default=stamp)
        mine = in_charge(js.frame_id) == self.arch and self.active
        if mine and not self.in_charge and self.plugin:
            # takes charge: a fresh, reset instance (the engine's closed loop does the same)
            self.ctrl = registry.create(self.arch, self.binding.params)
        self.in_charge = mine
        if mine:  # our states wake us, also if the sim's announcement is late or lost
            self.loop.set_wake(self.subs[T.JOINT_STATES], True)
        if mine and T.REFERENCE in self.subs:
            self._check_unchecked(stamp)  # this tick's, kept while another was in charge
            for topic, _ in self.inputs:
                self.loop.take(self.subs[topic])
        else:  # not ours: its inputs, and the next states, can wait a few ms
            if not self.named:
                self.loop.set_wake(self.subs[T.JOINT_STATES], False)
            if self.loop.deadline is None:
                self.loop.set_deadline(time.monotonic() + IDLE_DRAIN, self._drain)
        if mine:
            self.last_state = stamp
            self.pending[stamp] = js
            if len(self.pending) > C.CONTROL_DEPTH:  # inputs that never came: give up the oldest
                del self.pending[min(self.pending)]
                self.waits.given_up += 1
            self._answer()
            if self.pending:  # an input is late: let it wake us
                self._count_wait(stamp)
                for topic, _ in self.inputs:
                    self.loop.set_wake(self.subs[topic], True)
        # After the command is out (off the round trip): take the next tick's reference if
        # it is there already (the generator publishes ahead of the states), so that the next
        # state finds it checked; forget the inputs of answered ticks.
        if mine and T.REFERENCE in self.subs:
            self.loop.take(self.subs[T.REFERENCE])
            self._check_unchecked()  # after a switch: the rest of what was kept unchecked
        keep = min(self.pending, default=stamp)
        for _, buf in self.inputs:
            for s in [s for s in buf if s < keep]:
                del buf[s]

    def _count_wait(self, stamp: int) -> None:
        """A state of ours (``stamp``, ns) came while states are pending: if it waits itself,
        count which input is missing and say so in a warning (from the WARN_AFTER-th wait
        on, at most every WARN_EVERY wall s): the cause of missed ticks the sim reports (a
        starved trajectory generator shows as waits for the reference)."""
        ref, ff = stamp not in self.refs, stamp not in self.forces
        if not self.waits.count(ref, ff):
            return  # answered already: the state still pending is an older one, counted then
        now = time.monotonic()
        if self.waits.waited >= WARN_AFTER and now - self.warned_at >= WARN_EVERY:
            self.warned_at = now
            newest = max(self.refs, default=-1)
            behind = (f"the newest reference is of tick {C.tick_of(newest, self.period_ns)}"
                      if newest >= 0 else "no reference queued")
            missing = " and ".join(x for x, m in (("reference", ref), ("foot forces", ff)) if m)
            self.log.warning(
                f"the {missing} of tick {C.tick_of(stamp, self.period_ns)} came after its "
                f"state ({behind}); answering when it comes. So far: {self.waits.cause()}")

    def _answer(self) -> None:
        """Compute and publish the command of each pending state whose inputs are there."""
        for stamp in sorted(self.pending):
            ref = self.refs.get(stamp)
            ff = self.forces.get(stamp)
            hip = self.hips.get(stamp) if self.plugin else None
            if ref is None or ff is None or (self.plugin and hip is None):
                continue
            js = self.pending.pop(stamp)
            C.fill_obs(self.obs, T.JOINT_STATES, js.position, js.velocity, js.effort)
            C.fill_obs(self.obs, T.FOOT_FORCES, ff.position, ff.velocity, ff.effort)
            if hip is not None:
                C.fill_obs(self.obs, T.HIP_STATES, hip.position, hip.velocity, hip.effort)
            r = T.split_reference(ref.position, ref.velocity)
            self.theta_d[:] = r["theta"]
            self.theta_vel_d[:] = r["theta_vel"]
            tr = _trace.TRACER
            if tr is not None:
                tr.mark(_trace.LAW0, stamp=stamp)
            if self.plugin:
                t = C.tick_of(stamp, self.period_ns) * self.period
                cmd = call_law(self.ctrl, t, self.obs, self.theta_d, self.theta_vel_d)
                c = (T.drive_command_columns(cmd) if has_gains(cmd)
                     else T.command_columns(cmd[C_TFF]))
            elif self.drive:
                pd_pf_drive_command(self.gains, self.theta_d, self.theta_vel_d, self.cmd)
                c = T.drive_command_columns(self.cmd)
            else:
                self._law()
                c = T.command_columns(self.demand)
            if tr is not None:
                tr.mark(_trace.LAW1, stamp=stamp)
            data = self.cmd_codec.encode(stamp, self.arch, c.position, c.velocity, c.effort)
            data = self.cmd_signer.sign(data)
            if tr is not None:
                tr.mark(_trace.PUB0, T.JOINT_COMMANDS, stamp)
            self.pub.publish(data)
            if tr is not None:
                tr.mark(_trace.PUB1, T.JOINT_COMMANDS, stamp)
            self.answered += 1
        if not self.pending:
            for topic, _ in self.inputs:
                self.loop.set_wake(self.subs[topic], False)

    def _law(self) -> None:
        control_law(self.code, self.gains, self.obs, self.theta_d, self.theta_vel_d, self.l1,
                    self.l2, self.demand)


def has_gains(cmd: np.ndarray) -> bool:
    """True if the drive command (6, 6, 2) sets a drive gain (else it is torque-only)."""
    return bool(cmd[C_KP].any() or cmd[C_KD].any() or cmd[C_KF].any())


def _start(node: ControllerNode) -> None:
    if node.autostart:
        node.trigger_configure()
        node.trigger_activate()


def _finish(node: ControllerNode, code: int) -> int:
    node._check_unchecked()  # what was kept unchecked is counted like the rest
    node.log.info(f"stopping after {node.answered} commands ({node.waits.text()}; "
                  f"{node.skipped_inputs} inputs of ticks no state needed skipped unchecked); "
                  f"inputs: {node.guard.summary()}")
    if node.pub is not None:
        node.pub.wait_for_all_acked(Duration(seconds=1))
    return code


def _main(architecture: str, args: list[str] | None) -> int:
    return run_node(node_of(architecture), lambda: ControllerNode(architecture), args,
                    start=_start, finish=_finish)


def main_controller(name: str, args: list[str] | None = None) -> int:
    """Entry point of the node of any registered controller (``hexapod controllers``): the
    built-ins' nodes, or a plug-in's law run per tick as the engine runs it."""
    from hexapod_common.core.params import check_controller

    try:
        name = check_controller(name)
    except ParameterError as err:
        print(f"controller_node: error: {err}", file=sys.stderr)
        return 2
    return _main(name, args)


def main_pd_p(args: list[str] | None = None) -> int:
    """Entry point of ``pd_p_controller``."""
    return _main("pd_p", args)


def main_pd_pf(args: list[str] | None = None) -> int:
    """Entry point of ``pd_pf_controller``."""
    return _main("pd_pf", args)


if __name__ == "__main__":
    sys.exit(main_controller(sys.argv[1] if len(sys.argv) > 1 and not
                             sys.argv[1].startswith("-") else "pd_pf"))
