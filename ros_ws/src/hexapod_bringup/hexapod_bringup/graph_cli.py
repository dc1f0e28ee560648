"""`hexapod switch` and `hexapod status`: the command line against a running graph.

Both commands ask the sim on its local channel (core/switch_channel.py; the sim's end is
hexapod_sim/channel_service.py): no ROS context, no DDS discovery, so they answer in a
fraction of a second (docs/benchmarks.md, CLI). Without a sim's channel they say at once
that nothing runs, or, when DDS participants are on the domain (a sim without its channel,
another user's graph), look for the graph over ROS for at most :data:`NO_CHANNEL_WAIT` s.

* ``hexapod switch NAME``: any controller on the graph (docs/controllers.md, "Naming":
  node ``<name>_controller`` for a built-in controller, else the node ``NAME``); the sim
  configures and activates a lifecycle node first if needed (its ``change_state``
  service), a plain node must be running; then it sets its own ``run.controller`` through
  the checks of a ``ros2 param set`` and hands over at the next tick boundary. One line on
  success; a one-line error and exit code 2 otherwise.
* ``hexapod status``: the nodes the sim sees, the controller nodes with the lifecycle state
  of each managed one (``pd_p (node pd_p_controller, inactive)``), the mode, simulated
  time, controller in charge, missed and late ticks.

This module imports nothing heavy (no numpy, no rclpy, no parameter table): the switch and
status of `hexapod` (cli.py) and of scripts/hexapod start with it alone. The graph's process
launcher is cmd_graph.py.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from typing import Any, Sequence

from hexapod_common.core.controller_names import name_of, node_of, reserved_hint
from hexapod_common.core.errors import HexapodError

from .cli_args import OneLineParser, number
from .join_options import controller_arg

#: Wall s `hexapod status` gives DDS discovery to find every node of the graph (over ROS).
DISCOVERY_TIME = 1.5
#: Wall s `hexapod switch`/`status` look for a graph over ROS when no sim listens on its
#: local channel but DDS participants are on the domain (a sim without its channel, another
#: user's graph): a clear error then, not the whole --timeout.
NO_CHANNEL_WAIT = 1.5
#: Wall s `hexapod status` waits at most for the controllers' lifecycle states.
STATE_TIME = 2.0
#: ``--timeout`` of ``switch`` and ``status``: seconds, finite and positive.
TIMEOUT = number(0.0, 3600.0, "a timeout (s)", lo_open=True)


class GraphError(HexapodError):
    """The graph (or one of its nodes) is not there or does not answer."""


# --------------------------------------------------------------------------- ROS helpers


def _ros_node(name: str) -> Any:
    import rclpy
    from rclpy.node import Node

    from hexapod_common.runtime.dds_profile import TOOL_PARTICIPANT_IDS
    from hexapod_common.runtime.hot_loop import configure_middleware

    configure_middleware(TOOL_PARTICIPANT_IDS)  # not a just-killed node's participant id
    rclpy.init(args=[])
    return Node(f"{name}_{os.getpid()}", start_parameter_services=False)


def _call(node: Any, srv_type: Any, service: str, request: Any, timeout: float,
          missing: str, answer_timeout: float | None = None) -> Any:
    """Call ``service`` once it shows up (GraphError ``missing`` if not within ``timeout``
    s); its answer within ``answer_timeout`` s (default ``timeout``)."""
    import rclpy

    client = node.create_client(srv_type, service)
    if not client.wait_for_service(timeout_sec=timeout):
        raise GraphError(missing)
    future = client.call_async(request)
    answer_timeout = timeout if answer_timeout is None else answer_timeout
    rclpy.spin_until_future_complete(node, future, timeout_sec=answer_timeout)
    if not future.done() or future.result() is None:
        raise GraphError(f"{service} did not answer within {answer_timeout:g} s")
    return future.result()


def _domain() -> str:
    return os.environ.get("ROS_DOMAIN_ID", "0")


def ensure_active(node: Any, controller: str, timeout: float) -> str:
    """Configure and activate ``<controller>_controller`` if needed; its state before."""
    from lifecycle_msgs.msg import State, Transition
    from lifecycle_msgs.srv import ChangeState, GetState

    name = node_of(controller)
    missing = (f"controller node {name} is not running on ROS_DOMAIN_ID={_domain()} "
               f"(no /{name}/get_state within {timeout:g} s): start it first")
    state = _call(node, GetState, f"/{name}/get_state", GetState.Request(), timeout,
                  missing).current_state
    before = state.label
    steps = {State.PRIMARY_STATE_UNCONFIGURED: [Transition.TRANSITION_CONFIGURE,
                                                 Transition.TRANSITION_ACTIVATE],
             State.PRIMARY_STATE_INACTIVE: [Transition.TRANSITION_ACTIVATE],
             State.PRIMARY_STATE_ACTIVE: []}
    if state.id not in steps:
        raise GraphError(f"{name} is in lifecycle state '{state.label}': cannot activate it")
    for transition in steps[state.id]:
        req = ChangeState.Request()
        req.transition.id = transition
        ok = _call(node, ChangeState, f"/{name}/change_state", req, timeout, missing).success
        if not ok:
            raise GraphError(f"{name} refused lifecycle transition {transition}")
    return before


def _is_lifecycle(node: Any, controller: str, timeout: float) -> bool:
    """Whether ``controller`` is served by a lifecycle node (a node with a ``get_state``
    service: a built-in's node, or one that joined); a plain node is switched to as it is.

    Waits up to ``timeout`` for this process to discover the node, then up to 2 s for its
    services (they are announced one by one; ``get_state`` may come after the others)."""
    target = node_of(controller)
    end = time.monotonic() + timeout
    services_by: float | None = None
    while time.monotonic() < end:
        if target in node.get_node_names():
            services_by = services_by or time.monotonic() + 2.0
            offers = _offers_get_state(node, target)
            if offers is None:  # gone meanwhile
                return False
            if offers:
                return True
            if time.monotonic() > services_by:
                return False
        time.sleep(0.05)
    return False


def _offers_get_state(node: Any, target: str) -> bool | None:
    """Whether node ``target`` offers ``/<target>/get_state`` as ``node`` sees it now (None
    if ``node`` does not see ``target``)."""
    try:
        services = node.get_service_names_and_types_by_node(target, "/")
    except Exception:  # noqa: BLE001 - not discovered, or gone meanwhile
        return None
    return any(name == f"/{target}/get_state" for name, _ in services)


def lifecycle_states(node: Any, nodes: Sequence[str], timeout: float) -> dict[str, str]:
    """The lifecycle state (``unconfigured``, ``inactive``, ``active``, ...) of each of
    ``nodes`` that is a lifecycle node (one that offers ``get_state``), asked through that
    service; ``unknown`` for one that did not answer within ``timeout`` s. Plain nodes are
    left out."""
    from lifecycle_msgs.srv import GetState
    import rclpy

    clients = {n: node.create_client(GetState, f"/{n}/get_state") for n in nodes
               if _offers_get_state(node, n)}
    futures: dict[str, Any] = {}
    end = time.monotonic() + timeout
    while time.monotonic() < end and not (
            len(futures) == len(clients) and all(f.done() for f in futures.values())):
        for n, client in clients.items():
            if n not in futures and client.service_is_ready():
                futures[n] = client.call_async(GetState.Request())
        rclpy.spin_once(node, timeout_sec=0.05)
    states = {}
    for n in clients:
        f = futures.get(n)
        answer = f.result() if f is not None and f.done() else None
        states[n] = answer.current_state.label if answer is not None else "unknown"
    return states



#: Set by scripts/hexapod to the project's root when it runs switch/status without
#: scripts/env.sh (the venv's Python on the sources alone: enough for the local channel).
LEAN_ENV = "HEXAPOD_LEAN_ENV"


def _ros_env() -> None:
    """Make rclpy importable: in a lean start (:data:`LEAN_ENV`), re-execute this command
    through scripts/env.sh (the ROS overlay, the wheels' libraries); else nothing."""
    root = os.environ.pop(LEAN_ENV, "")
    if not root:
        return
    cmd = f'source "{root}/scripts/env.sh" && exec python -m hexapod_bringup.cli "$@"'
    sys.stdout.flush()
    os.execvp("bash", ["bash", "-c", cmd, "hexapod", *sys.argv[1:]])


def _ask_sim(text: str, timeout: float) -> str | None:
    """The sim's answer to one request on its local channel (core/switch_channel.py: no ROS
    context, no discovery, milliseconds); None if no sim listens there."""
    from hexapod_common.core.switch_channel import ChannelError, request

    try:
        answer = request(text, _domain(), timeout)
    except ChannelError as err:
        raise GraphError(str(err)) from err
    if answer is None:
        return None
    code, _, body = answer.partition(" ")
    if code != "ok":
        raise GraphError(body)
    return body


def _nothing_runs() -> str | None:
    """The error when no DDS participant of this machine is on this domain, else None (then
    the tools look for the graph over ROS, for at most :data:`NO_CHANNEL_WAIT` s).

    A live participant listens on its shared-memory ports (``fastrtps_port<N>``, N from the
    domain and its participant id) and holds the lock of each (``<port>_el``); a port left
    by a killed process has nobody's lock. Read from /proc/locks: no lock is taken here."""
    from hexapod_common.runtime.dds_profile import (DOMAIN_PARTICIPANT_IDS, SHM_DIR,
                                                    domain_id_from_env, unicast_ports)

    domain = domain_id_from_env()
    ports = set()
    for pid in DOMAIN_PARTICIPANT_IDS:
        for port in unicast_ports(domain, pid):
            try:
                ports.add((SHM_DIR / f"fastrtps_port{port}_el").stat().st_ino)
            except OSError:
                continue
    if ports:
        import re

        try:
            with open("/proc/locks") as f:  # "1: FLOCK ADVISORY WRITE <pid> 00:1b:<inode> ..."
                held = {int(m[1]) for m in re.finditer(r" [0-9a-f]+:[0-9a-f]+:(\d+) ",
                                                       f.read())}
        except OSError:
            return None  # cannot tell: look over ROS
        if ports & held:
            return None
    return f"nothing runs on ROS_DOMAIN_ID={_domain()}: no sim, no ROS node"


def switch(controller: str, timeout: float = 10.0) -> str:
    """Hand control to ``controller`` (see module docstring); the line to print.

    Through the sim's local switch channel (the sim checks, activates a lifecycle node and
    sets its run.controller: hexapod_sim/channel_service.py); through ROS services if no sim
    listens there (a sim without its channel, another user's graph), after at most
    :data:`NO_CHANNEL_WAIT` s for the sim to show up."""
    answer = _ask_sim(f"switch {controller}", timeout)
    if answer is not None:
        return answer
    nothing = _nothing_runs()
    if nothing:
        raise GraphError(nothing)
    _ros_env()
    import rclpy
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import GetParameters, SetParameters

    node = _ros_node("hexapod_switch")
    try:
        wait = min(timeout, NO_CHANNEL_WAIT)
        missing = (f"no hexapod_sim running on ROS_DOMAIN_ID={_domain()} (no switch channel "
                   f"and no /hexapod_sim/set_parameters within {wait:g} s)")
        current = _call(node, GetParameters, "/hexapod_sim/get_parameters",
                        GetParameters.Request(names=["run.controller"]), wait,
                        missing, answer_timeout=timeout).values[0].string_value
        before = (ensure_active(node, controller, timeout)
                  if _is_lifecycle(node, controller, timeout) else "active")
        value = ParameterValue(type=ParameterType.PARAMETER_STRING, string_value=controller)
        req = SetParameters.Request(parameters=[Parameter(name="run.controller", value=value)])
        end = time.monotonic() + timeout
        while True:  # a just-activated controller takes a moment to show in the sim's graph
            result = _call(node, SetParameters, "/hexapod_sim/set_parameters", req, timeout,
                           missing).results[0]
            if result.successful or " refused: " not in result.reason \
                    or time.monotonic() > end:
                break
            time.sleep(0.05)
        if not result.successful:
            raise GraphError(f"hexapod_sim refused run.controller = {controller}: "
                             f"{result.reason}")
        activated = ("" if before == "active"
                     else f"; {node_of(controller)} was {before}, now active")
        if current == controller:
            return f"{controller} already in charge{activated}"
        return f"switching {current} -> {controller} at the next tick{activated}"
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


def status(timeout: float = 5.0) -> tuple[list[str], dict[str, str] | None]:
    """Nodes seen in the graph and the sim's status values (None if no sim answered), with
    the controller nodes (``controller_nodes``, a comma list) and the lifecycle state of each
    lifecycle one (``controller_states``: ``node=state,...``).

    From the sim's local channel (hexapod_sim/channel_service.py: the sim's view of the
    graph, the states asked by the sim); over ROS if no sim listens there (one
    ``/hexapod/status`` and this tool's own discovery, :data:`NO_CHANNEL_WAIT` s at most
    to find the graph)."""
    answer = _ask_sim("status", timeout)
    if answer is not None:
        import json

        doc = json.loads(answer)
        return list(doc["nodes"]), dict(doc["status"])
    nothing = _nothing_runs()
    if nothing:
        raise GraphError(nothing)
    _ros_env()
    return _status_over_ros(min(timeout, NO_CHANNEL_WAIT), timeout)


def _status_over_ros(wait: float, timeout: float) -> tuple[list[str], dict[str, str] | None]:
    """:func:`status` through a ROS node of this process: ``wait`` s for a status."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from hexapod_common.runtime.conversions import statuses
    from hexapod_common.core.topics import STATUS

    node = _ros_node("hexapod_status")
    got: list[DiagnosticArray] = []
    try:
        # Every node of the graph publishes its status there: keep the sim's.
        node.create_subscription(DiagnosticArray, STATUS, lambda m: got.extend(
            [m] if any(s.name == "hexapod_sim" for s in m.status) else []), 10)
        start = time.monotonic()
        end = start + wait
        # until a status came and discovery had DISCOVERY_TIME s to find every node (a node
        # that joined is seen later than the status of the sim that answers at once)
        while (not got or time.monotonic() < start + min(DISCOVERY_TIME, wait)) \
                and time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=0.1)
        # This process discovers the graph node by node: the status came once the sim was
        # seen, the others may not be yet. The sim's status names what it sees.
        ours = set(node.get_node_names())
        from hexapod_common.runtime.controller_graph import controller_nodes

        sim = [s for s in statuses(got[-1]) if s.name == "hexapod_sim"] if got else []
        values = dict(sim[0].values) if sim else {}
        # the sim's view (it has long discovered every node) and this tool's
        seen = sorted(set(controller_nodes(node))
                      | set(filter(None, values.get("controller_nodes", "").split(","))))
        states = lifecycle_states(node, seen, min(timeout, STATE_TIME)) if sim else {}
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    theirs = {n for n in values.get("nodes", "").split(",") if n}
    nodes = sorted(n for n in ours | theirs
                   if not n.startswith(("hexapod_status_", "_")))
    if not sim:
        return nodes, None
    nodes = sorted(set(nodes) | set(seen))
    return nodes, values | {"level": sim[0].level, "message": sim[0].message,
                            "controller_nodes": ",".join(seen),
                            "controller_states": ",".join(f"{n}={st}"
                                                          for n, st in states.items())}


# --------------------------------------------------------------------------- commands


def _cmd_switch(args: argparse.Namespace) -> int:
    print(switch(args.controller, args.timeout))
    return 0


def _cmd_status(args: argparse.Namespace) -> int:
    nodes, st = status(args.timeout)
    if st is None:
        seen = ", ".join(nodes) if nodes else "no nodes"
        print(f"hexapod status: no sim on ROS_DOMAIN_ID={_domain()}: no switch channel and "
              f"no /hexapod/status within {min(args.timeout, NO_CHANNEL_WAIT):g} s ({seen} "
              f"seen)", file=sys.stderr)
        return 1
    if args.json:
        import json

        print(json.dumps({"nodes": nodes, "status": st}, indent=1))
        return 0
    print(f"nodes: {', '.join(nodes)}")
    states = dict(item.split("=", 1) for item in st["controller_states"].split(",") if item)
    listed = [n for n in st.get("controller_nodes", "").split(",") if n]
    print("controllers: " + (", ".join(
        f"{name_of(n)} (node {n}{', ' + states[n] if n in states else ''}"
        f"{', in charge' if name_of(n) == st['controller'] else ''})"
        for n in listed if name_of(n) is not None) or "none on the graph"))
    for n in listed:  # a node named as a built-in controller: what it is not
        if name_of(n) is None:
            print(f"note: {reserved_hint(n)}")
    end = st.get("end_tick", "none")
    until = f" of {end}" if end not in ("none", "") else "; runs until stopped"
    print(f"{st['mode']} mode, sim time {float(st['sim_time']):.3f} s (tick {st['tick']}"
          f"{until}), "
          f"controller {st['controller']}, missed {st['missed_ticks']}, late {st['late_ticks']},"
          f" fallback {st['fallback']}, real-time factor {st['real_time_factor']}: "
          + (st["message"] if st["level"] == "ok" else f"{st['level'].upper()}: {st['message']}"))
    return 0


def add_parser(subparsers: Any) -> None:
    """Register ``switch`` and ``status`` with the ``hexapod`` CLI."""
    sp = subparsers.add_parser("switch", help="hand control to another controller node")
    sp.add_argument("controller", type=controller_arg,
                    help="a controller on the graph: pd_p, pd_pf or a node that joined "
                         "(docs/controllers.md)")
    sp.add_argument("--timeout", type=TIMEOUT, default=10.0,
                    help="seconds to wait for the sim and the controller (default 10)")
    sp.set_defaults(func=_cmd_switch)
    st = subparsers.add_parser("status", help="what runs in the graph, mode, ticks")
    st.add_argument("--timeout", type=TIMEOUT, default=5.0,
                    help="seconds to wait for /hexapod/status (default 5)")
    st.add_argument("--json", action="store_true", help="print JSON")
    st.set_defaults(func=_cmd_status)


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m hexapod_bringup.graph_cli switch|status ...``: the same subcommands as
    ``hexapod``, without importing the rest of the CLI (the engine, numba, plots: seconds);
    ``hexapod switch|status`` (cli.py) runs this. Errors are one line and exit code 2."""
    parser = OneLineParser(prog="hexapod")
    add_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    try:
        return int(args.func(args))
    except (HexapodError, OSError) as err:
        print(f"hexapod {args.command}: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"hexapod {args.command}: interrupted", file=sys.stderr)
        return 130


__all__ = ["GraphError", "NO_CHANNEL_WAIT", "add_parser", "ensure_active", "lifecycle_states",
           "main", "status", "switch"]


if __name__ == "__main__":
    sys.exit(main())
