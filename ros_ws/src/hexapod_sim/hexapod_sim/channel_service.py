"""The sim's end of the local channel (core/switch_channel.py): `hexapod switch` and
`hexapod status` without a ROS context in the tool.

Requests are served at the sim's tick boundaries (once the tick is out) and, while no tick
goes out (before tick 0, a long lockstep wait), from a timer every :data:`IDLE_LOOK` s:

* ``switch NAME``: the naming rule (core/controller_names.py) and the node's presence; a
  lifecycle node (one that offers ``get_state``) is asked its state and, if it is
  unconfigured or inactive, configured and activated through its ``change_state`` service;
  then ``run.controller`` is set on the sim through its own parameter checks (those of a
  ``ros2 param set``). Answer: ``ok switching A -> B at the next tick[; N was S, now
  active]``, ``ok B already in charge`` or ``error <one line>``.
* ``status``: the sim's status values (those of ``/hexapod/status``), its view of the graph's
  nodes, and the lifecycle state of each controller node that has one, asked through its
  ``get_state`` service. Answer: ``ok <JSON>`` (:func:`status_doc`).

Each request is a small job stepped at every serve until it answers: service calls are
asynchronous, so the sim's thread never waits for a controller.
"""
from __future__ import annotations

import json
import os
import time
from typing import Any

from rclpy.node import NodeNameNonExistentError
from rclpy.parameter import Parameter

from hexapod_common.core.controller_names import check_name, node_of
from hexapod_common.core.errors import ParameterError
from hexapod_common.core.switch_channel import SwitchServer

#: Wall s between two looks at the channel from the timer, while no tick boundary serves it.
IDLE_LOOK = 0.05
#: Wall s a request waits for one lifecycle service (get_state, change_state) to answer.
SERVICE_TIMEOUT = 2.0
#: Wall s a status waits for the controllers' lifecycle states (then ``unknown``).
STATE_TIME = 1.0
#: Wall s a switch to a node just activated retries run.controller while the sim's view of
#: the graph catches up (its subscription shows, then matches).
ACTIVATION_SETTLE = 3.0


def _domain() -> str:
    return os.environ.get("ROS_DOMAIN_ID", "0")


class _Job:
    """One request in progress: :meth:`step` returns the answer once there is one."""

    def step(self, now: float) -> str | None:  # pragma: no cover - interface
        raise NotImplementedError


class ChannelService:
    """Serve the local channel of one sim node (``sim``: the SimNode, for its graph queries,
    parameters, ticks and status)."""

    def __init__(self, sim: Any, server: SwitchServer | None) -> None:
        self.sim = sim
        self.server = server
        self.state_clients: dict[str, Any] = {}
        self.change_clients: dict[str, Any] = {}
        self.jobs: list[tuple[_Job, str]] = []  # (job, reply address)
        self.served_at = 0.0
        if server is not None:
            sim.create_timer(IDLE_LOOK, self._idle, clock=sim.steady)

    # ------------------------------------------------------------------ clients
    def _kept_client(self, kept: dict[str, Any], srv_type: Any, service: str) -> Any:
        """The client of ``service`` kept in ``kept``, made (and the wait set refreshed) on
        first use: a client made at request time may send before the service has matched
        it, and wait forever."""
        client = kept.get(service)
        if client is None:
            client = kept[service] = self.sim.create_client(srv_type, service)
            self.sim.loop.refresh()
        return client

    def state_client(self, node: str) -> Any:
        """The (kept) client of node ``node``'s lifecycle ``get_state`` service."""
        from lifecycle_msgs.srv import GetState

        return self._kept_client(self.state_clients, GetState, f"/{node}/get_state")

    def change_client(self, node: str) -> Any:
        """The (kept) client of node ``node``'s lifecycle ``change_state`` service."""
        from lifecycle_msgs.srv import ChangeState

        return self._kept_client(self.change_clients, ChangeState, f"/{node}/change_state")

    # ------------------------------------------------------------------ serving
    @property
    def busy(self) -> bool:
        """Whether requests are in progress (served at every boundary until answered)."""
        return bool(self.jobs)

    def _idle(self) -> None:
        if time.monotonic() - self.served_at > IDLE_LOOK:
            self.serve()

    def serve(self) -> None:
        """Step the requests in progress and take new ones."""
        assert self.server is not None
        now = self.served_at = time.monotonic()
        waiting = []
        for job, addr in self.jobs:
            answer = job.step(now)
            if answer is None:
                waiting.append((job, addr))
            else:
                self.server.reply(addr, answer)
        self.jobs = waiting
        for text, addr in self.server.poll():
            job = self._job(text)
            answer = job.step(now) if isinstance(job, _Job) else job
            if answer is None:
                self.jobs.append((job, addr))  # type: ignore[arg-type]
            else:
                self.server.reply(addr, answer)

    def _job(self, text: str) -> _Job | str:
        parts = text.split()
        if parts == ["status"]:
            return StatusJob(self)
        if len(parts) == 2 and parts[0] == "switch":
            return SwitchJob(self, parts[1])
        return f"error unknown request {text[:60]!r} (expected 'switch NAME' or 'status')"

    def close(self) -> None:
        """Close and remove the socket."""
        if self.server is not None:
            self.server.close()


class _StateQuery:
    """One node's lifecycle state asked through its kept get_state client."""

    def __init__(self, service: ChannelService, node: str, until: float) -> None:
        self.client = service.state_client(node)
        self.future: Any = None
        self.until = until

    def step(self, now: float) -> str | None:
        """The state's label once answered; ``unknown`` past the deadline; else None."""
        if self.future is None and self.client.service_is_ready():
            from lifecycle_msgs.srv import GetState

            self.future = self.client.call_async(GetState.Request())
        if self.future is not None and self.future.done():
            res = self.future.result()
            return res.current_state.label if res is not None else "unknown"
        return "unknown" if now > self.until else None


class StatusJob(_Job):
    """``status``: the sim's status and the lifecycle state of each controller node."""

    def __init__(self, service: ChannelService) -> None:
        self.service = service
        sim = service.sim
        self.values = sim.status()
        until = time.monotonic() + STATE_TIME
        self.queries = {n: _StateQuery(service, n, until)
                        for n in sim.controller_node_list() if sim.is_lifecycle(n)}
        self.states: dict[str, str] = {}

    def step(self, now: float) -> str | None:
        for n, q in list(self.queries.items()):
            state = q.step(now)
            if state is not None:
                self.states[n] = state
                del self.queries[n]
        if self.queries:
            return None
        return "ok " + json.dumps(status_doc(self.values, self.states))


def status_doc(st: Any, states: dict[str, str]) -> dict[str, Any]:
    """What `hexapod status --json` prints: the nodes seen and the sim's status values, with
    ``level``, ``message`` and ``controller_states`` (``node=state,...``)."""
    values = dict(st.values)
    nodes = sorted(n for n in values.get("nodes", "").split(",") if n)
    return {"nodes": nodes, "status": values | {
        "level": st.level, "message": st.message,
        "controller_states": ",".join(f"{n}={s}" for n, s in sorted(states.items()))}}


class SwitchJob(_Job):
    """``switch NAME``: checks, activation of a lifecycle node, then run.controller.

    Phases: ``start`` (naming rule, presence, in charge already), ``state`` (a lifecycle
    node's get_state), ``change`` (configure and/or activate, one change_state at a time),
    ``set`` (run.controller through the sim's checks; retried for :data:`ACTIVATION_SETTLE`
    s after an activation, while the sim's view of the node catches up)."""

    def __init__(self, service: ChannelService, to: str) -> None:
        self.service = service
        self.sim = service.sim
        self.to = to
        self.node = node_of(to)
        self.phase = "start"
        self.query: _StateQuery | None = None
        self.before = "active"  # the node's lifecycle state when asked
        self.transitions: list[int] = []
        self.sent = 0  # the transition in progress
        self.change: Any = None  # its change_state call
        self.change_until = 0.0
        self.settle_until = 0.0
        self.asked_again = False  # a "plain" node found to be a lifecycle one after all
        self.error: str | None = None
        try:
            check_name(to)
        except ParameterError as err:
            self.error = str(err)

    def step(self, now: float) -> str | None:
        if self.error is not None:
            return f"error {self.error}"
        if self.phase == "start":
            return self._start(now)
        if self.phase == "state":
            assert self.query is not None
            state = self.query.step(now)
            return None if state is None else self._after_state(state, now)
        if self.phase == "change":
            return self._change(now)
        return self._set(now)

    def _start(self, now: float) -> str | None:
        sim = self.sim
        absent = sim.controller_absent(self.to)
        if absent:  # also the one in charge: a node that has left takes no ticks
            return f"error {absent}"
        if self.to == sim.ticks.in_charge and sim.ticks.pending_controller is None:
            return f"ok {self.to} already in charge"
        if sim.is_lifecycle(self.node):
            self._ask(now)
            return None
        return self._set(now)  # a plain node: present, subscribed and matched

    def _ask(self, now: float) -> None:
        self.phase = "state"
        self.query = _StateQuery(self.service, self.node, now + SERVICE_TIMEOUT)

    def _after_state(self, state: str, now: float) -> str | None:
        from lifecycle_msgs.msg import Transition

        self.before = state
        steps = {"unconfigured": [Transition.TRANSITION_CONFIGURE,
                                  Transition.TRANSITION_ACTIVATE],
                 "inactive": [Transition.TRANSITION_ACTIVATE], "active": []}
        if state == "unknown":
            return (f"error {self.node} did not answer its get_state within "
                    f"{SERVICE_TIMEOUT:g} s")
        if state not in steps:
            return f"error {self.node} is in lifecycle state '{state}': cannot activate it"
        self.transitions = steps[state]
        if not self.transitions:
            return self._set(now)
        self.phase = "change"
        return self._change(now)

    def _change(self, now: float) -> str | None:
        """Send the next lifecycle transition once the last one succeeded."""
        from lifecycle_msgs.srv import ChangeState

        if self.change is not None:
            if not self.change.done():
                if now > self.change_until:
                    return (f"error {self.node} did not answer its change_state within "
                            f"{SERVICE_TIMEOUT:g} s")
                return None
            res = self.change.result()
            if res is None or not res.success:
                return f"error {self.node} refused lifecycle transition {self.sent}"
            self.change = None
            if not self.transitions:
                self.settle_until = now + ACTIVATION_SETTLE
                return self._set(now)
        client = self.service.change_client(self.node)
        if not client.service_is_ready():
            if not self.change_until:
                self.change_until = now + SERVICE_TIMEOUT
            if now > self.change_until:
                return f"error {self.node} offers no change_state service"
            return None
        self.sent = self.transitions.pop(0)
        req = ChangeState.Request()
        req.transition.id = self.sent
        self.change = client.call_async(req)
        self.change_until = now + SERVICE_TIMEOUT
        return None

    def _set(self, now: float) -> str | None:
        """Set run.controller through the sim's checks and say what happens."""
        self.phase = "set"
        sim = self.sim
        if now < self.settle_until and sim.controller_unready(self.to):
            return None  # the sim's view of the node catches up with its activation
        old = sim.ticks.in_charge
        result = sim.set_parameters([Parameter("run.controller", value=self.to)])[0]
        if not result.successful:
            if not self.settle_until and not self.asked_again and sim.is_lifecycle(self.node):
                # taken for a plain node before its lifecycle services were discovered
                # (they are announced one by one): ask its state as a lifecycle node's
                self.asked_again = True
                self._ask(now)
                return None
            return f"error hexapod_sim refused run.controller = {self.to}: {result.reason}"
        sim.log.info(f"switch to {self.to} requested through the local switch channel")
        activated = ("" if self.before == "active"
                     else f"; {self.node} was {self.before}, now active")
        return f"ok switching {old} -> {self.to} at the next tick{activated}"


def lifecycle(sim: Any, node: str) -> bool:
    """Whether ``node`` is on ``sim``'s graph with a lifecycle ``get_state`` service."""
    try:
        services = sim.get_service_names_and_types_by_node(node, "/")
    except NodeNameNonExistentError:
        return False
    return any(s == f"/{node}/get_state" for s, _ in services)


__all__ = ["ChannelService", "IDLE_LOOK", "StatusJob", "SwitchJob", "lifecycle",
           "status_doc"]
