"""Node ``hexapod_sim``: a thin shell around the tick state machine (core/tick_machine.py).

Per tick k it publishes the sample of tick k (``/hexapod/joint_states``, whose frame_id names
the controller in charge and the source of the torque, core/labels.py; foot_forces,
hip_states, ``/clock``), authenticated; passes each command of ``/hexapod/joint_commands``
(checked by the input guard) and each expired deadline to the machine, which applies the
torque and integrates (lockstep / realtime, missed, held, fallback, switch: see there).
Around it: parameters (``run.controller`` through the same readiness check as ``hexapod
switch``; ``switch_at``/``switch_to`` script a switch), the local switch channel,
``/hexapod/status`` every 0.5 s, the start (tick 0 once ``wait_for``'s nodes are matched,
at most ``startup_timeout`` s, on both sides: each reader says so through its
``inputs_matched`` service, runtime/inputs_matched.py) and the end summary (log,
``summary_path`` JSON). Exit codes: 0, 1 (diverged, or another error), 2 (bad parameters).
"""
from __future__ import annotations

import os
import sys
import time
from typing import Any, Callable

import numpy as np
from rclpy.clock import Clock, ClockType
from rclpy.duration import Duration
from rclpy.node import Node, NodeNameNonExistentError
from rclpy.parameter import Parameter
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.qos import ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from hexapod_common.runtime import conversions as C
from hexapod_common.core import msg_checks as M
from hexapod_common.core import topics as T
from .core.actuator import saturate
from .core.physics import Physics
from .core.recorder_pace import RecorderPace
from hexapod_common.core.errors import CdrError, ParameterError
from hexapod_common.core.controller_names import (check_name, engine_names, name_of, node_of,
                                                  reserved_hint)
from hexapod_common.core.params import N_LEGS, HexapodParams, check_controller, controller_names
from hexapod_common.core.switch_channel import ChannelError, SwitchServer
from .channel_service import ChannelService, lifecycle
from hexapod_common.core import cdr
from hexapod_common.core import trace as _trace
from hexapod_common.core.labels import COMMANDED
from .core.tick_machine import LIVENESS_LOOK, SWITCH_WINDOW, Outcome, TickMachine, Wait
from .core.uneven_ground import GroundDraws, pairs_for
from hexapod_common.runtime.hot_loop import FastLogger, HotLoop
from hexapod_common.runtime import inputs_matched
from hexapod_common.runtime.input_guard import InputGuard
from hexapod_common.runtime.liveness import Liveness, launcher_pids
from hexapod_common.runtime.node_main import run_node
from hexapod_common.runtime.controller_graph import controller_nodes, controllers_on_graph
from hexapod_common.runtime.controller_params import ControllerParamsReader
from hexapod_common.runtime.param_topic import ParamAnnouncer
from hexapod_common.runtime.ros_params import ParamBinding, declare_node_param, declare_params
from hexapod_common.runtime.rt_sched import use_rt_priority

#: Endpoints each node of the graph shows once it is ready to run (subscriptions, publications).
#: A controller node's endpoints (also those of a joined controller in charge at start).
CONTROLLER_ENDPOINTS = ((T.JOINT_STATES, T.REFERENCE), (T.JOINT_COMMANDS,))
#: A registered plug-in's node (the project's controller node running its law): every
#: sample topic of the engine's observation (it answers inputs_matched, as the built-ins').
PLUGIN_ENDPOINTS = ((T.JOINT_STATES, T.FOOT_FORCES, T.HIP_STATES, T.REFERENCE),
                    (T.JOINT_COMMANDS,))
EXPECTED_ENDPOINTS: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    "trajectory_generator": ((T.JOINT_STATES,), (T.REFERENCE,)),
    "pd_p_controller": ((T.JOINT_STATES, T.FOOT_FORCES, T.REFERENCE), (T.JOINT_COMMANDS,)),
    "pd_pf_controller": ((T.JOINT_STATES, T.FOOT_FORCES, T.REFERENCE), (T.JOINT_COMMANDS,)),
    "metrics": ((T.JOINT_STATES, T.FOOT_FORCES, T.HIP_STATES, T.REFERENCE,
                 T.JOINT_COMMANDS, T.ACTIVE_CONTROLLER, T.STATUS), ()),
    # the markers node draws every state from t = 0: tick 0 waits for its subscriptions too
    "markers": ((T.JOINT_STATES, T.FOOT_FORCES, T.HIP_STATES), ()),
}
STATUS_PERIOD = 0.5  # wall s between /hexapod/status messages
#: Wall s between two looks at the local switch channel (a socket read per look, ~5-10 us
#: each here) and at whether /clock has a subscriber (publishing to none costs ~15 us):
#: per tick at 1-2 kHz lockstep that was a few % of the sim's thread.
LOOK_PERIOD = 0.002
INPUTS_TIMEOUT = 5.0  # s tick 0 waits for the readers' side of the matching (inputs_matched)
#: s tick 0 waits more for a joined controller in charge (it has no inputs_matched service):
#: for its command writer to match the recorder's reader. 0.5 s lost the first ~30 of 2000
#: commands to the recorder on a loaded two-worker CI run, twice in two stops.
JOINED_MATCH_WAIT = 1.5
#: Wall s the sim waits for a silent recorder that is RECORDER_LAG ticks behind before it
#: goes on without it (core/recorder_pace.py): longer than any stall of a live recorder.
RECORDER_PATIENCE = 5.0
#: Wall s between two looks, while a tick is held, at the writers of /hexapod/recorded: when a
#: recorder left the graph (closed, or dropped as dead) or joined it, the hold ends.
RECORDER_LOOK = 0.25
INPUTS_RETRY = 0.02  # s between two questions to a node whose readers have not matched
#: The nodes a lockstep tick waits for besides the controller in charge (while they live).
TRAJECTORY_NODE = "trajectory_generator"
RECORDER_NODE = "metrics"


class AfterSendLog:
    """The log of what happens between ticks (the tick machine, parameter changes): while
    ``running()`` (realtime ticks going out), a line is said once the next tick's messages
    are out (``queue`` is run by :meth:`SimNode._send`, within a period): a log line costs
    tens of microseconds (console and /rosout), which a realtime tick's round trip cannot
    spare. Otherwise at once."""

    def __init__(self, log: FastLogger, queue: list[Callable[[], None]],
                 running: Callable[[], bool]) -> None:
        self.log = log
        self.queue = queue
        self.running = running

    def _say(self, say: Callable[[str], None], message: str) -> None:
        if self.running():
            self.queue.append(lambda: say(message))
        else:
            say(message)

    def info(self, message: str) -> None:
        """Log at INFO."""
        self._say(self.log.info, message)

    def warning(self, message: str) -> None:
        """Log at WARN."""
        self._say(self.log.warning, message)

    def error(self, message: str) -> None:
        """Log at ERROR."""
        self._say(self.log.error, message)


class SimNode(Node):
    """The simulator: physics, tick publishing, command intake, modes, switch, fallback."""

    def __init__(self) -> None:
        super().__init__("hexapod_sim")
        self.log = FastLogger(self.get_logger().name)
        self.guard = InputGuard(self, self.log)  # authenticates and checks every input
        # What happens between two ticks (log lines, the switch announcement, parameter
        # records) goes out just after the next tick's messages: off the round trip.
        self.after_send: list[Callable[[], None]] = []
        self.later = AfterSendLog(self.log, self.after_send, self._ticking_in_realtime)
        # run.controller names any controller on the graph (core/controller_names.py), not
        # only the engine's: checked for syntax here, for presence by _check_change.
        checks = {"run.controller": lambda name, value: check_name(value, name)}
        self.binding = ParamBinding(self, declare_params(self, checks=checks), self._on_params,
                                    check=self._check_change, log=self.later, checks=checks)
        self.stop_at_end = declare_node_param(self, "stop_at_end")
        if self.stop_at_end and self.params.run.duration == 0:
            raise ParameterError("run.duration", 0.0, "a duration in (0, 1e+06] s when "
                                 "stop_at_end is true (0: a run until stopped)")
        wait_for = declare_node_param(self, "wait_for")
        self.wait_for = [n.strip() for n in wait_for.split(",") if n.strip()]
        self.startup_timeout = declare_node_param(self, "startup_timeout")
        # A scripted switch (scripts/run_graph.sh): at the first tick at or after switch_at
        # (sim s), the sim sets its own run.controller to switch_to, exactly as a
        # `hexapod switch` would; deterministic, so the run can be reproduced.
        self.switch_at = declare_node_param(self, "switch_at")
        self.switch_to = declare_node_param(self, "switch_to")
        if self.switch_to:
            check_controller(self.switch_to)
        end = self.params.run.duration if self.stop_at_end else float("inf")
        if self.switch_to and not (0.0 <= self.switch_at <= end):
            raise ParameterError("switch_at", self.switch_at,
                                 f"a time in [0, run.duration = {end:g}] s")
        self.summary_path = declare_node_param(self, "summary_path")
        self.ground = self._uneven_ground()
        # SCHED_FIFO for the control path when asked (the launcher does in realtime mode).
        self.rt = use_rt_priority(self, self.log)
        p = self.params
        self.mode = p.sim.mode
        self.period = p.sim.control_period
        self.period_ns = int(round(self.period * 1e9))
        self._warm_up()
        # The tick rules (lockstep/realtime, misses, hold, fallback, switch): core/tick_machine.py
        self.ticks = TickMachine(Physics(p, self.ground), lambda: self.params, self.later, self,
                                 stop_at_end=self.stop_at_end)

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
            # Volatile: matches every writer, transient-local or volatile (a node publishing
            # with rclpy's defaults is heard; docs/controllers.md, "QoS").
            C.TOPIC_QOS[T.JOINT_COMMANDS].volatile_subscriber(C.HISTORY_DEPTH))
        # Lockstep: a tick waits while the recorder is too far behind (core/recorder_pace.py).
        self.pace = RecorderPace(T.RECORDER_LAG, RECORDER_PATIENCE)
        self.recorded_sub = None
        self.recorders = 0  # writers of /hexapod/recorded when a recorder last spoke
        # Lockstep waits for the living (runtime/liveness.py): the launcher's processes by
        # pid, any other node by the graph's node list.
        self.liveness = Liveness(self.get_node_names)
        if self.mode == "lockstep":
            self.recorded_sub = self.loop.subscribe(
                DiagnosticArray, T.RECORDED, self._on_recorded,
                C.RECORDED_QOS.subscriber(C.RECORDED_QOS.depth))
        self.steady = Clock(clock_type=ClockType.STEADY_TIME)
        # `hexapod switch` and `hexapod status` ask here first (core/switch_channel.py,
        # channel_service.py): no ROS context per call.
        server: SwitchServer | None = None
        try:
            server = SwitchServer.open(os.environ.get("ROS_DOMAIN_ID", "0"))
        except (ChannelError, OSError) as err:
            self.log.warning(f"no local switch channel ({err}); `hexapod switch` and "
                             f"`hexapod status` use ROS services and topics instead")
        self.channel = ChannelService(self, server)
        self.next_look = 0.0  # monotonic s: the next look at the channel and /clock
        self.clock_wanted = True  # /clock has a subscriber (looked at every LOOK_PERIOD)
        self.create_timer(STATUS_PERIOD, self._publish_status, clock=self.steady)

        self.prepared: tuple[int, int, list[tuple[Any, bytes]]] = (0, 0, [])
        self._rtf = (time.monotonic(), 0)
        self.rtf = 0.0
        # Start values now; changes at the tick boundary that applies them (ready()).
        self.announcer = ParamAnnouncer(self, self.period, deferred=True)
        # A joined controller's own parameters, read through its parameter services when it
        # takes over, go into the bag as a 'controller' record (runtime/controller_params.py).
        self.controller_params = ControllerParamsReader(self, self.loop, self._record_controller)

    # ------------------------------------------------------------------ helpers
    @property
    def params(self) -> HexapodParams:
        """The node's current (validated) parameters."""
        return self.binding.params

    def _uneven_ground(self) -> GroundDraws | None:
        """The node parameters ground_seed / ground_spread as draws (None: uniform ground):
        the factors `hexapod montecarlo --first-seed K` uses, so seed K replays here bit for
        bit (enough pairs per foot for the run: uneven_ground.pairs_for)."""
        seed = declare_node_param(self, "ground_seed")
        spread = declare_node_param(self, "ground_spread")
        if seed < 0:
            return None
        p = self.params
        span = p.run.duration if self.stop_at_end else 3600.0
        pairs = 2 * pairs_for(span, p.cycle_time)
        self.log.info(f"uneven ground: seed {seed}, spread {spread:g} (sigma of ln factor), "
                      f"{pairs} touchdowns per foot drawn")
        return GroundDraws.draw(seed, spread, pairs)

    def _warm_up(self) -> None:
        """Run the compiled functions once so tick 0 does not pay for loading them."""
        probe = Physics(self.params)
        probe.observe()
        out = np.empty((N_LEGS, 2))
        saturate(np.zeros((N_LEGS, 2)), 1.0, out)
        probe.advance_tick(out)

    def run_after_send(self) -> None:
        """Say what waited for the tick's messages to go out (:class:`AfterSendLog`, the
        switch announcement, parameter records), in order."""
        todo, self.after_send[:] = list(self.after_send), []
        for say in todo:
            say()

    def _ticking_in_realtime(self) -> bool:
        """Whether realtime ticks are going out (then log lines wait for the next send)."""
        ticks = getattr(self, "ticks", None)
        return (ticks is not None and self.mode == "realtime" and ticks.started
                and not ticks.finished)

    def _check_change(self, changes: list[Parameter]) -> str | None:
        """Refuse a ``run.controller`` change to a controller that cannot take over now."""
        for p in changes:
            if p.name == "run.controller" and isinstance(p.value, str):
                # the controller in charge again: its node must still be there
                why = (self.controller_absent(p.value) if p.value == self.ticks.in_charge
                       else self.controller_unready(p.value))
                if why:
                    return f"run.controller = {p.value!r} refused: {why}"
        return None

    def controller_absent(self, controller: str) -> str:
        """Why ``controller`` cannot take over: its node is not on the graph ('' if it is)."""
        node = node_of(controller)
        if node in self.get_node_names():
            return ""
        domain = os.environ.get("ROS_DOMAIN_ID", "0")
        in_charge = (f", though {controller} is in charge (its node has left the graph or "
                     f"never joined)" if controller == self.ticks.in_charge else "")
        reserved = (f"; {reserved_hint(controller)}" if name_of(controller) is None
                    and controller in self.get_node_names() else "")
        return (f"no controller node {node} on ROS_DOMAIN_ID={domain}{in_charge} (controllers "
                f"on the graph: {', '.join(controllers_on_graph(self)) or 'none'}){reserved}")

    def controller_unready(self, controller: str) -> str:
        """Why ``controller`` cannot take over at the next tick ('' if it can).

        Asked of the graph by node (tens of microseconds), not by topic: the endpoint
        infos by topic cost ~0.3 ms here, which a realtime tick cannot spare."""
        absent = self.controller_absent(controller)
        if absent:
            return absent
        node = node_of(controller)
        domain = os.environ.get("ROS_DOMAIN_ID", "0")
        try:
            subs = {t for t, _ in self.get_subscriber_names_and_types_by_node(node, "/")}
            pubs = {t for t, _ in self.get_publisher_names_and_types_by_node(node, "/")}
        except NodeNameNonExistentError:  # gone between the two questions
            return f"{node} is not running on ROS_DOMAIN_ID={domain}"
        if T.JOINT_STATES not in subs:
            if self.is_lifecycle(node):
                return (f"{node} is not active (no subscription to {T.JOINT_STATES}): "
                        f"activate it first (hexapod switch {controller} does)")
            return (f"{node} does not subscribe to {T.JOINT_STATES} (yet: a node just "
                    f"started may not be discovered fully): try again")
        if T.JOINT_COMMANDS not in pubs:
            return f"{node} does not publish {T.JOINT_COMMANDS}"
        if (self.pub[T.JOINT_STATES].get_subscription_count()
                < self.count_subscribers(T.JOINT_STATES)):
            return f"{node}'s subscription to {T.JOINT_STATES} is not matched yet: try again"
        return ""

    def _on_params(self, p: HexapodParams, names: set[str]) -> None:
        if "run.controller" in names and p.run.controller != self.ticks.in_charge:
            if self.joined(p.run.controller):
                self.controller_params.prepare(p.run.controller)
            self.ticks.request_switch(p.run.controller)
            self.later.info(f"switch to {p.run.controller} requested: takes effect at "
                          f"the next tick boundary")
        if any(n.startswith(("ground.", "actuator.")) for n in names):
            self.ticks.request_params(p)

    # ------------------------------------------------------------------ start
    def graph_missing(self) -> list[str]:
        """What is still missing before tick 0 may be published (empty when ready)."""
        missing = []
        for node in self.wait_for:
            subs, pubs = self._endpoints(node)
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

    def _endpoints(self, node: str) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """(subscriptions, publications) node ``node`` of ``wait_for`` shows once ready."""
        if node in EXPECTED_ENDPOINTS:
            return EXPECTED_ENDPOINTS[node]
        name = name_of(node)
        if name is not None and name not in engine_names() and name in controller_names():
            return PLUGIN_ENDPOINTS
        return CONTROLLER_ENDPOINTS if node == node_of(self.ticks.in_charge) else ((), ())

    def _check_controllers(self) -> None:
        """Ask each expected controller its lifecycle state (and say if it is not active).

        This also makes the first exchange between the two processes (slower: shared memory
        is mapped) happen before tick 0 rather than at the first tick after a switch.
        """
        from lifecycle_msgs.srv import GetState

        names = [n for n in self.wait_for if n.endswith("_controller") and self.is_lifecycle(n)]
        # Kept for the switch channel's checks (channel_service.py)
        clients = [self.channel.state_client(n) for n in names]
        futures = [c.call_async(GetState.Request()) for c in clients]
        self.loop.spin(until=lambda: all(f.done() for f in futures), timeout=5.0)
        for name, future in zip(names, futures):
            state = future.result().current_state.label if future.done() else "not answering"
            if state != "active":
                self.log.warning(f"{name} is {state}: it answers only once active")

    def _joined_in_charge(self) -> bool:
        """Whether the controller in charge is a joined node (not the engine's) of
        ``wait_for``."""
        return (node_of(self.ticks.in_charge) in self.wait_for
                and self.ticks.in_charge not in engine_names())

    def _wait_inputs_matched(self) -> None:
        """Wait (at most INPUTS_TIMEOUT s) until every node of ``wait_for`` that reads this
        node's per-tick topics says its readers have matched our writers on its side
        (runtime/inputs_matched.py: our side matching first is not enough, and the samples of
        ticks sent before the other side matched were lost to it), and every controller
        says its command writer has matched every command reader this node sees. Starts
        anyway, with an error naming who is not ready, after the timeout."""
        from std_srvs.srv import Trigger

        names = [n for n in self.wait_for  # the nodes that answer inputs_matched
                 if (n in EXPECTED_ENDPOINTS or self._endpoints(n) is PLUGIN_ENDPOINTS)
                 and set(self._endpoints(n)[0]) & set(inputs_matched.SIM_TOPICS)]
        clients = {n: self.create_client(Trigger, inputs_matched.service_name(n))
                   for n in names}
        self.loop.refresh()
        waiting = {n: "no answer" for n in names}
        asked: dict[str, Any] = {}
        next_ask = dict.fromkeys(names, 0.0)  # monotonic s: not asked again before
        # A joined controller in charge at tick 0 (waited for) writes commands from its start:
        # its writer counts even before this node's command reader has matched it (else a
        # recorder that had not matched it either passed, and lost its first ~30 commands).
        commander = int(self._joined_in_charge())

        def ready() -> bool:
            now = time.monotonic()
            for name, client in clients.items():
                if name not in waiting:
                    continue
                future = asked.get(name)
                if future is None:
                    if now >= next_ask[name] and client.service_is_ready():
                        asked[name] = client.call_async(Trigger.Request())
                elif future.done():
                    res = future.result()
                    del asked[name]  # asked again after INPUTS_RETRY s unless ready
                    next_ask[name] = now + INPUTS_RETRY
                    if res is None:
                        continue
                    text = inputs_matched.opened(self.guard, name, res.success, res.message)
                    if text is None:
                        waiting[name] = "its answers are not authentic (dropped)"
                    elif res.success:
                        short = inputs_matched.behind(
                            text, {T.JOINT_COMMANDS: max(commander,
                                                         self.cmd_sub.get_publisher_count()),
                                   T.REFERENCE: self.count_publishers(T.REFERENCE),
                                   inputs_matched.WRITER + T.JOINT_COMMANDS:
                                       self.count_subscribers(T.JOINT_COMMANDS)})
                        if short:
                            waiting[name] = short
                        else:
                            del waiting[name]
                    else:
                        waiting[name] = f"readers of {text} not matched"
            return not waiting
        if not self.loop.spin(until=ready, timeout=INPUTS_TIMEOUT) and not self.loop.stopped:
            self.log.error("starting although not every reader has matched this node's "
                           "writers (its first ticks may be lost to it): " + "; ".join(
                               f"{n}: {why}" for n, why in waiting.items()))
        for client in clients.values():
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
            self._wait_inputs_matched()
            if self.loop.stopped:
                return
            if self._joined_in_charge():
                # A joined controller in charge has no inputs_matched service: give its
                # readers the time our side took to match ours, so tick 0 is not lost to it.
                self.loop.spin(until=lambda: False, timeout=JOINED_MATCH_WAIT)
                if self.loop.stopped:
                    return
        self.log.info(
            f"{self.mode} mode, {1 / self.period:g} Hz control, {self.ticks.in_charge} in charge, "
            f"run.duration {self.params.run.duration:g} s"
            + (" (stops there)" if self.stop_at_end else " (runs until stopped)"))
        if self.joined(self.ticks.in_charge):
            self.controller_params.read(self.ticks.in_charge, 0)
        if self.rt is not None:  # every peer matched: receive threads made meanwhile too
            late = self.rt.refresh()
            if late:
                self.log.info(f"rt_priority: SCHED_FIFO also for {', '.join(late)}")
        self.ticks.start(time.monotonic())
        self._rtf = (self.ticks.wall_start, 0)
        self._prepare()
        self._send()

    def joined(self, controller: str) -> bool:
        """Whether ``controller``'s node joined the graph (its own parameters go into the
        bag when it takes over): any controller not built in, and a built-in one whose node
        the launcher did not start (a node in its place: docs/controllers.md, "Naming")."""
        if controller not in engine_names():
            return True
        pids = launcher_pids()
        return bool(pids) and node_of(controller) not in pids

    def is_lifecycle(self, node: str) -> bool:
        """Whether ``node`` is on the graph with a lifecycle ``get_state`` service."""
        return lifecycle(self, node)

    def _record_controller(self, controller: str, tick: int, values: dict[str, Any]) -> None:
        """Publish a joined controller's parameters as a 'controller' record of its tick."""
        from hexapod_common.core.param_log import ParamRecord

        a = self.announcer
        rec = ParamRecord(node_of(controller), "controller", tick,
                          T.stamp_ns(tick * self.period), values)
        from hexapod_common.core.param_log import RECORD_NAME

        status = C.Status(f"{RECORD_NAME}/{rec.node}", "ok", rec.kind, rec.to_map())
        a.pub.publish(self.guard.signed(a.signer, C.encode_statuses(rec.stamp_ns, [status])))
        a.sent += 1
        self.later.info(f"{controller}'s parameters at tick {tick} recorded "
                        f"({len(values)} values)" if values else
                        f"{controller}'s parameters could not be read: recorded none")

    def _announce(self) -> None:
        """Publish the controller in charge on /hexapod/active_controller (signed)."""
        self.pub[T.ACTIVE_CONTROLLER].publish(self.guard.signed(
            self.signers[T.ACTIVE_CONTROLLER], String(data=self.ticks.in_charge)))

    # ------------------------------------------------------------------ ticks
    def _prepare(self) -> None:
        """Sample the current tick and serialize its messages (not sent yet)."""
        if _trace.TRACER is not None:
            _trace.TRACER.mark(_trace.PREP0)
        k, stamp, obs, frame = self.ticks.sample()
        cs = self.codecs
        out = []
        # Foot forces first: the controller needs them with the joint states that wake it.
        # joint_states names the controller in charge and where its effort came from
        # (core/labels.py: the bare name when the controller commanded it).
        for topic, frame_id in ((T.FOOT_FORCES, ""), (T.JOINT_STATES, frame),
                                (T.HIP_STATES, "")):
            c = T.state_columns(obs, topic)
            out.append((self.pub[topic], self.signers[topic].sign(
                cs[topic].encode(stamp, frame_id, c.position, c.velocity, c.effort))))
        # rosgraph_msgs/Clock is a bounded type: Fast DDS refuses a sample longer than 12
        # bytes, so /clock carries no tag. No node of the graph acts on it (the trajectory
        # generator follows the authenticated states; the recorder writes /clock from them):
        # sent while someone subscribes (nodes on sim time, ROS tools).
        if self.clock_wanted:
            out.append((self.pub[T.CLOCK], C.encode_clock(stamp)))
        self.prepared = (k, stamp, out)

    def _send(self) -> None:
        """Publish the prepared tick and arm the deadline of its command (lockstep: unless
        the recorder is too far behind; then when it has caught up)."""
        k, _, out = self.prepared
        if self.pace.recorded is not None and self._held_for_recorder(k):
            return
        self.ticks.sending(time.monotonic())  # the round trip counts from here
        tr = _trace.TRACER
        if tr is not None:
            tr.mark(_trace.PUB0, stamp=self.ticks.stamp)
        for pub, data in out:
            pub.publish(data)
            if tr is not None:
                tr.mark(_trace.PUB1, pub.topic_name, self.ticks.stamp)
        wait, when = self.ticks.sent(time.monotonic())
        if wait is Wait.STOP:
            self.loop.set_deadline(None)
            self.loop.stop()
        elif wait is Wait.TIMEOUT:
            self.loop.set_deadline(when, self._on_timeout)
        else:
            self.loop.set_deadline(when, self._on_period_end)
        self.run_after_send()

    def _on_command(self, data: bytes) -> None:
        if self.ticks.finished:
            return
        cmd = self.guard.joint_state(T.JOINT_COMMANDS, data, self.period_ns)
        if cmd is None:  # dropped (and counted) by the guard
            return
        demand = cmd.effort
        if len(demand) != len(T.JOINT_NAMES):  # a drive command (docs/controllers.md)
            demand = T.drive_command(cmd.position, cmd.velocity, cmd.effort)
        got = self.ticks.command(cmd.stamp_ns, cmd.frame_id, demand, time.monotonic())
        if got is Outcome.AHEAD:
            self.guard.drop(T.JOINT_COMMANDS, M.BAD_STAMP,
                            f"stamp {cmd.stamp_ns * 1e-9:.9g} s is ahead of the current tick")
        elif got is Outcome.SEND:
            due = self.ticks.release_at()  # sim.lockstep_max_rtf: not before then
            if due > time.monotonic():
                self.loop.set_deadline(due, self._send)
            else:
                self._send()
        elif got is Outcome.SCHEDULE:  # realtime: tick 1 goes out now
            self.loop.set_deadline(0.0, self._on_period_end)

    def _held_for_recorder(self, k: int) -> bool:
        """Lockstep: whether tick ``k`` waits for the recorder (core/recorder_pace.py); if so
        :meth:`_send` runs again when it is heard, at the next look or when it is given up."""
        now = time.monotonic()
        if not self.pace.behind(k):
            self.pace.hold_until(k, now)  # goes out (and ends a hold)
            return False
        n = self.recorded_sub.get_publisher_count()
        if n != self.recorders:
            # One left (closed, or dropped by its peers when its lease ran out), or one
            # joined (it records nothing while this tick is held, so says nothing): wait
            # for nobody until the next word of a recorder. Asked before the recorder's
            # silence is judged: a killed recorder's lease and the sim's patience with a
            # silent one are both 5 s, and the one that has left is not "given up on".
            self.log.info(f"a recorder {'joined' if n > self.recorders else 'left'} the "
                          f"graph at tick {k} ({n} now): lockstep waits for the "
                          f"recorders' next word")
            self.pace.forget(now)
            self.recorders = n
            return False
        gave_up, left = self.pace.gave_up, self.pace.left
        until = self.pace.hold_until(k, now, lambda: self.liveness.alive(RECORDER_NODE),
                                     self.params.sim.lockstep_timeout)
        if until is None:
            if self.pace.left > left:
                self.log.info(f"a recorder left the graph at tick {k} (its node is gone): "
                              f"lockstep waits for the recorders' next word")
            elif self.pace.gave_up > gave_up:
                self.log.warning(
                    f"the recorder has said nothing for {now - self.pace.heard_at:.1f} s "
                    f"and is more than {T.RECORDER_LAG} ticks behind tick {k}: going on "
                    f"without waiting for it (its bag may lack ticks: run_graph says so)")
            return False
        self.loop.set_deadline(min(until, now + RECORDER_LOOK), self._send)
        return True

    def _on_recorded(self, data: bytes) -> None:
        """The recorder's progress: a held tick goes out once it is close enough."""
        payload = self.guard.payload(T.RECORDED, data)
        if payload is None:  # dropped (and counted) by the guard
            return
        try:
            stamp, _ = cdr.decode_diagnostic_array(payload)
        except CdrError as err:
            self.guard.drop(T.RECORDED, M.UNDECODABLE, str(err))
            return
        self.pace.heard(C.tick_of(stamp, self.period_ns), time.monotonic(), self.ticks.tick)
        self.recorders = self.recorded_sub.get_publisher_count()  # who a hold waits for
        if self.pace.holding:
            self._send()

    def _on_timeout(self) -> None:
        """Lockstep: no command for the current tick yet: wait on while the controller in
        charge and the trajectory generator live (up to sim.lockstep_timeout), else a missed
        tick."""
        m = self.ticks
        again = m.waiting(time.monotonic(),
                          self.liveness.alive(node_of(m.in_charge), TRAJECTORY_NODE))
        if again is not None:
            self.loop.set_deadline(again, self._on_timeout)
            return
        m.timeout()
        self._send()

    def _on_period_end(self) -> None:
        """Realtime: the period of the current tick is over: send the next tick."""
        self.ticks.period_end(time.monotonic())
        self._send()

    # ------------------------------------------------------------------ the machine's hooks
    def at_boundary(self, tick: int) -> None:
        """Switch requests (local channel, scripted switch) at a tick boundary.

        The local channel is served once the next tick is out (``run_after_send``), in the
        time the sim waits for that tick's command: a request's checks and parameter change
        take ~0.2-0.8 ms of the sim's thread, which served here delayed the next tick's
        states (the switch tick's command came late at 20 of 50 switches at 1 kHz,
        docs/benchmarks.md). The switch then takes effect at the following boundary."""
        now = time.monotonic()
        if now >= self.next_look:
            self.next_look = now + LOOK_PERIOD
            self.clock_wanted = self.pub[T.CLOCK].get_subscription_count() > 0
            if self.channel.server is not None:
                self.after_send.append(self.channel.serve)
        elif self.channel.busy:
            self.after_send.append(self.channel.serve)
        if self.controller_params.pending:
            self.after_send.append(self.controller_params.poll)
        if self.switch_to and tick * self.period >= self.switch_at - 1e-12:
            to, self.switch_to = self.switch_to, ""
            result = self.set_parameters([Parameter("run.controller", value=to)])[0]
            if not result.successful:
                self.log.error(f"scripted switch to {to!r} refused: {result.reason}")

    def switched(self, tick: int, old: str, new: str) -> None:
        """Announce the new controller in charge (once the tick is out: the controllers go
        by the states' frame_id, the recorder by the first state naming the new one)."""
        self.after_send.append(self._announce)
        if self.joined(new):
            self.controller_params.read(new, tick)

    def ready(self, tick: int) -> None:
        """Parameter changes announced at their tick (once it is out); the next tick's
        messages serialized."""
        if self.announcer.pending:  # most ticks have nothing to announce
            self.after_send.append(lambda: self.announcer.flush(tick))
        self._prepare()

    # ------------------------------------------------------------------ status
    def status(self) -> C.Status:
        """The sim's diagnostic status (also logged as the summary)."""
        m = self.ticks
        now = time.monotonic()
        k = m.tick
        last_wall, last_tick = self._rtf
        if now - last_wall > 1e-3:
            self.rtf = (k - last_tick) * self.period / (now - last_wall)
        self._rtf = (now, k)
        if not m.started:
            missing = self.graph_missing() if self.wait_for else []
            level, msg = "warn", "waiting for the graph" + (
                f" (not there yet: {'; '.join(missing)})" if missing else "")
        elif m.fallback:
            level, msg = "error", f"{m.in_charge} silent: joint damping fallback"
        elif m.silent_ticks:
            level, msg = "warn", f"{m.in_charge} silent: holding the last torque"
        elif self.pace.holding:
            level, msg = "warn", (f"holding tick {k} for the recorder (behind by more than "
                                  f"{T.RECORDER_LAG} ticks)")
        elif (self.mode == "lockstep" and not m.finished and not m.answered
              and now - m.published_at > LIVENESS_LOOK):
            level, msg = "warn", (
                f"waiting {now - m.published_at:.1f} s for {m.in_charge}'s command of tick "
                f"{k} (its nodes are alive; at most sim.lockstep_timeout = "
                f"{self.params.sim.lockstep_timeout:g} s)")
        elif m.finished:
            level, msg = "ok", "finished"
        else:
            level, msg = "ok", "running"
        g = self.guard
        if level == "ok" and g.warn_now():  # what is true now: not a publisher that left
            level = "warn"
        if g.drops.total or g.outsiders or g.key is None:
            msg = f"{msg}; {g.now()}"
        values = {
            "mode": self.mode, "sim_time": f"{k * self.period:.6f}", "tick": str(k),
            "controller": m.in_charge, "missed_ticks": str(m.missed),
            "late_ticks": str(m.late), "on_time_ticks": str(m.on_time),
            "fallback": "on" if m.fallback else "off",
            "fallback_episodes": str(m.fallback_episodes),
            "switches": str(m.switches), "missed_after_switch": str(m.missed_after_switch),
            "real_time_factor": f"{self.rtf:.3f}",
            "resyncs": str(m.resyncs),
            "end_tick": str(m.end_tick) if self.stop_at_end else "none",
            "round_trip_median_ms": f"{m.latency_ms(0.5):.3f}",
            "round_trip_p99_ms": f"{m.latency_ms(0.99):.3f}",
            "stop_at_end": str(self.stop_at_end).lower(),
            "foreign_commands": str(m.foreign), **self.guard.values(),
            "controller_nodes": self._controller_nodes(),
            # the sim's view of the graph (a `hexapod status` just started may not have
            # discovered every node yet); asked by node name, tens of microseconds
            "nodes": ",".join(sorted(n for n in self.get_node_names() if not n.startswith("_"))),
        }
        return C.Status("hexapod_sim", level, msg, values)

    def _say_if_gone(self, m: TickMachine) -> None:
        """Say once when the silent controller in charge has left the graph (a node that
        joined is not the launcher's: nobody else reports its death)."""
        gone = (m.started and not m.finished and bool(m.silent_ticks)
                and node_of(m.in_charge) not in self.get_node_names())
        if gone and getattr(self, "_gone_said", None) != m.in_charge:
            self._gone_said = m.in_charge
            self.later.error(f"{m.in_charge} (node {node_of(m.in_charge)}) has left the graph "
                             f"while in charge: `hexapod switch` to another controller")
        elif not m.silent_ticks:
            self._gone_said = None

    def _controller_nodes(self) -> str:
        """The controller nodes on the graph as this node sees them (comma list), looked up
        again when the set of nodes changed or a second went by (a node list costs tens of
        microseconds; a node's publishers are discovered after the node itself)."""
        nodes = tuple(sorted(self.get_node_names_and_namespaces()))
        now = time.monotonic()
        cached = getattr(self, "_controllers_seen", None)
        if cached is None or cached[0] != nodes or now > cached[2]:
            cached = self._controllers_seen = (nodes, ",".join(controller_nodes(self)),
                                               now + 1.0)
        return cached[1]

    def controller_node_list(self) -> list[str]:
        """The controller nodes on the graph as this node sees them."""
        return [n for n in self._controller_nodes().split(",") if n]

    def _publish_status(self) -> None:
        m = self.ticks
        if (m.started and not m.silent_ticks and m.source == COMMANDED
                and m.tick > m.switch_tick + 1 and self.joined(m.in_charge)):
            # a joined controller whose commands passed the guard (the torque acting now is
            # its command, not the one before the switch to it): not an outsider
            self.guard.vouch(node_of(m.in_charge))
        self._say_if_gone(m)
        self.guard.refresh()
        data = C.encode_statuses(max(self.ticks.stamp, 0), [self.status()])
        self.pub[T.STATUS].publish(self.guard.signed(self.signers[T.STATUS], data))

    def summary(self) -> str:
        """One line: what ran, how many ticks were missed or late."""
        m = self.ticks
        k = m.tick
        wall = time.monotonic() - m.wall_start if m.started else 0.0
        rtf = k * self.period / wall if wall > 0 else 0.0
        return (f"stopped at tick {k} (t = {k * self.period:.3f} s) in {self.mode} mode: "
                f"{m.missed} missed, {m.late} late, {m.on_time} on time (realtime), "
                f"{m.fallback_episodes} fallback episodes, {m.switches} switches "
                f"({m.missed_after_switch} missed within {SWITCH_WINDOW} ticks after one), "
                f"{m.resyncs} resyncs, {self.pace.holds} holds for the recorder "
                f"({self.pace.held_s:.2f} s), {m.long_waits} long waits for a living "
                f"controller (longest {m.longest_wait:.2f} s; {m.cap_hits} at the cap); "
                f"round trip median {m.latency_ms(0.5):.2f} ms, p99 "
                f"{m.latency_ms(0.99):.2f} ms; wall {wall:.2f} s, real-time factor {rtf:.3f}; "
                f"{m.foreign} commands from a controller not in charge; inputs: "
                f"{self.guard.summary()}")

    def write_summary(self) -> None:
        """Write the machine's ``summary_doc`` and what the sim's inputs dropped and who
        published from outside the graph to ``summary_path`` (atomically), if set."""
        if not self.summary_path:
            return
        import json

        g = self.guard
        doc = self.ticks.summary_doc() | self.pace.as_dict() | {
            "dropped": {f"{t} ({c})": n for (t, c), n in g.drops.counts.items()},
            "outside_publishers": {t: sorted(n) for t, n in g.outsiders.items()},
            "authentication": "off" if g.key is None else "on"}
        record = self.ticks.physics.ground_record()
        if record is not None:  # seed, spread, touchdowns and the factors the feet used
            doc["ground"] = record.as_dict() | {"overflowed": record.overflowed}
        tmp = f"{self.summary_path}.tmp"
        with open(tmp, "w") as f:
            json.dump(doc, f)
        os.replace(tmp, self.summary_path)

    def flush(self, timeout: float = 2.0) -> None:
        """Wait (at most ``timeout`` s in all) until subscribers acknowledged every message."""
        end = time.monotonic() + timeout
        for pub in self.pub.values():
            left = max(0.0, end - time.monotonic())
            pub.wait_for_all_acked(Duration(nanoseconds=int(left * 1e9)))


def _finish(node: SimNode, code: int) -> int:
    """The summary (log, status, ``summary_path``), the last messages acknowledged."""
    node.run_after_send()  # what the last tick boundary had to say
    if node.ticks.started:
        node.log.info(node.summary())
        record = node.ticks.physics.ground_record()
        if record is not None:
            node.log.info(f"uneven ground: seed {record.draws.seed}, touchdowns per foot "
                          f"{list(record.touchdowns)}"
                          + (f"; MORE than the {record.draws.pairs} drawn: the last factors "
                             "were reused" if record.overflowed else ""))
        node._publish_status()
    try:
        node.write_summary()
    except OSError as err:
        node.log.error(f"cannot write the summary to {node.summary_path}: {err}")
    node.flush()
    node.channel.close()
    return code


def main(args: list[str] | None = None) -> int:
    """Entry point of ``hexapod_sim``."""
    return run_node("hexapod_sim", SimNode, args, start=SimNode.start, finish=_finish)


if __name__ == "__main__":
    sys.exit(main())
