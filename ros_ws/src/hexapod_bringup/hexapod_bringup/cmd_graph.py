"""`hexapod switch` and `hexapod status`, and a small launcher for the node graph.

* ``hexapod switch NAME``: any controller on the graph (docs/controllers.md: node
  ``<name>_controller`` for the engine's controllers, else the node ``NAME``); a lifecycle
  controller node is made active first (configured and activated through its
  ``change_state`` service if needed), a plain node must be running; then it sets
  ``run.controller`` on ``/hexapod_sim`` through the standard ``set_parameters`` service;
  the sim hands over at the next tick boundary. One line on success; a one-line error and
  exit code 2 if the sim or the controller does not answer within ``--timeout``.
* ``hexapod status``: waits for one ``/hexapod/status`` message and prints the nodes seen
  in the graph, the mode, simulated time, controller in charge, missed and late ticks.

:class:`GraphProcesses` starts node processes (forked from a fork server that imported the
node modules once, node_fork.py, or ``python -c 'from <module> import main'``; both with
``--ros-args``), keeps their logs, and stops them (SIGINT, then SIGTERM, then
SIGKILL); the graph launcher (graph_launcher.py, ``scripts/run_graph.sh``), the benchmark
and soak scripts and the graph tests use it. Every node it starts dies with it
(``PR_SET_PDEATHSIG``, lifeline.py), and with localhost-only discovery the nodes read a Fast
DDS profile written privately for this graph (dds_profile.py), never a shared file. It
gives a restarted node a participant id whose shared-memory ports do not exist. When one of its
nodes dies by a signal (no goodbye to the others), it holds the listener locks of that
node's shared-memory ports until the graph is stopped, so that no process started
meanwhile (``ros2 node list``) takes the dead node's participant id, and then deletes
those ports (dds_profile.PortFence).
"""
from __future__ import annotations

import argparse
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import weakref
from pathlib import Path
from typing import IO, Any, Callable, Sequence

from hexapod_common.core.errors import HexapodError
from hexapod_common.core.controller_names import engine_names, name_of, node_of
from hexapod_common.runtime.dds_profile import (LEASE_S, RESTART_PARTICIPANT_IDS,
                                                TOOL_PARTICIPANT_IDS, PortFence,
                                                domain_id_from_env, shm_locks,
                                                private_profile, remove_dead_shm,
                                                unused_participant_id)
from hexapod_common.runtime import node_fork
from hexapod_common.runtime.lifeline import PARENT_ENV

from .join_options import controller_arg
from .cli_args import OneLineParser, number

#: node name -> (module, entry point)
NODES: dict[str, tuple[str, str]] = {
    "hexapod_sim": ("hexapod_sim.sim_node", "main"),
    "trajectory_generator": ("hexapod_control.trajectory_node", "main"),
    "pd_p_controller": ("hexapod_control.controller_node", "main_pd_p"),
    "pd_pf_controller": ("hexapod_control.controller_node", "main_pd_pf"),
    "metrics": ("hexapod_metrics.metrics_node", "main"),
    "markers": ("hexapod_metrics.marker_node", "main"),
    "foxglove_bridge": ("hexapod_metrics.foxglove_node", "main"),
}
#: The modules the fork server imports once for every node it forks (node_fork.py): the
#: nodes' ROS-free code (numpy, numba, the engine, the laws, the codec, the bag writer), then
#: their compiled kernels (fork_preload.py). Not rclpy: it loads Fast DDS, whose threads
#: (its shared-memory watchdog among them) a fork does not copy.
PRELOAD = ("hexapod_common.core.cdr", "hexapod_common.core.controller_names",
           "hexapod_common.core.msg_auth", "hexapod_common.core.msg_checks",
           "hexapod_common.core.param_log", "hexapod_common.core.switch_channel",
           "hexapod_common.runtime.dds_profile", "hexapod_common.runtime.rt_sched",
           "hexapod_control.core.closed_loop", "hexapod_control.core.registry",
           "hexapod_control.core.waits", "hexapod_metrics.bag.writer",
           "hexapod_metrics.core.recording", "hexapod_metrics.core.log_times",
           "hexapod_sim.core.tick_machine", "hexapod_sim.core.drive",
           "hexapod_sim.core.uneven_ground", "hexapod_common.runtime.fork_preload")
#: A node's process: forked (node_fork.py) or, with a ``prefix`` or ``fork=False``, a new
#: interpreter.
NodeProcess = subprocess.Popen[bytes] | node_fork.ForkedNode
#: Scheduling niceness per node: the recorder yields the CPU to the control loop (it only
#: has to keep up on average; its queues absorb seconds of lag).
NICE = {"metrics": 10, "foxglove_bridge": 10}
#: Nodes that may run on simulated time (``-p use_sim_time:=true`` with ``use_sim_time``).
#: None of them reads ROS time (they work on the messages' stamps), and each /clock
#: subscription of a time source costs the lockstep loop ~10 % of its rate here, so it is
#: off by default.
SIM_TIME_NODES = ("trajectory_generator", "pd_p_controller", "pd_pf_controller", "metrics")
#: The nodes on the control path (main thread and Fast DDS threads under SCHED_FIFO) and all
#: the nodes that take ``rt_priority`` (hexapod_common/runtime/rt_sched.py; the others for
#: their Fast DDS threads only).
RT_NODES = ("hexapod_sim", "pd_p_controller", "pd_pf_controller", "trajectory_generator")
RT_PRIORITY_NODES = RT_NODES + ("metrics", "markers", "foxglove_bridge")
#: Wall s a node started in place of one that died by a signal waits after that death: until
#: the predecessor's participant lease has run out at its peers. A recorder forked 30-70 ms
#: after its predecessor's SIGKILL stalled the graph's deliveries to the others (Fast DDS:
#: 2 of 14 runs of the killed-recorder test; the predecessor still in the peers' view under
#: the same node name); 1 s later, 0 of 14, but a full suite run later stalled the graph for
#: 7 s and left PD-P&F silent for the rest of the run with the predecessor still in view
#: (the sim saw two recorders). After the lease, the peers have dropped the dead one.
RESTART_PAUSE = LEASE_S + 0.5
#: Wall s between two looks at a running node's shared-memory locks once they are known
#: (GraphProcesses.poll; the launcher's watch loop polls every 0.1 s).
LOCKS_REFRESH = 2.0


#: Wall s `hexapod status` gives DDS discovery to find every node of the graph.
DISCOVERY_TIME = 1.5
#: ``--timeout`` of ``switch`` and ``status``: seconds, finite and positive.
TIMEOUT = number(0.0, 3600.0, "a timeout (s)", lo_open=True)


class GraphError(HexapodError):
    """The graph (or one of its nodes) is not there or does not answer."""


# --------------------------------------------------------------------------- launcher


class GraphProcesses:
    """Start, watch and stop node processes of one graph (one ROS_DOMAIN_ID).

    ``env`` adds to the current environment (set ``ROS_DOMAIN_ID`` there); every node gets
    ``--params-file params`` if given and its log in ``log_dir/<name>.log``;
    ``use_sim_time`` passes ``use_sim_time:=true`` to the nodes of :data:`SIM_TIME_NODES`;
    ``rt_priority`` (> 0) passes ``rt_priority:=N`` to the nodes of :data:`RT_PRIORITY_NODES`;
    ``overrides`` (``"name:=value"``) go to every node. Unless ``env`` names a key file
    (``HEXAPOD_KEY_FILE``) or turns authentication off, the graph gets a fresh run key
    (``hexapod_common.core.msg_auth``), removed with this object. ``fork``: nodes are forked
    from the launcher's pre-imported fork server (node_fork.py: ~0.8 CPU s less per node);
    False starts each as a new interpreter.
    """

    def __init__(self, log_dir: str | os.PathLike[str], params: str | None = None,
                 env: dict[str, str] | None = None, use_sim_time: bool = False,
                 overrides: Sequence[str] = (), rt_priority: int = 0,
                 fork: bool = True) -> None:
        self.fork = fork
        self.log_dir = Path(log_dir)
        self.log_dir.mkdir(parents=True, exist_ok=True)
        self.params = params
        self.use_sim_time = use_sim_time
        self.rt_priority = int(rt_priority)
        self.overrides = tuple(overrides)
        self.env = {**os.environ, **(env or {})}
        self.env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        self.env["PYTHONUNBUFFERED"] = "1"
        # Here, not at the top: `hexapod switch` imports this module and must start fast.
        from hexapod_common.core.msg_auth import AUTH_ENV, KEY_ENV, new_key_file

        if self.env.get(AUTH_ENV, "on").lower() != "off" and not self.env.get(KEY_ENV):
            key = new_key_file()
            self.env[KEY_ENV] = str(key)
            weakref.finalize(self, shutil.rmtree, key.parent, True)
        self.env[PARENT_ENV] = str(os.getpid())
        self._private: Path | None = None
        if (self.env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
                and "FASTRTPS_DEFAULT_PROFILES_FILE" not in self.env):
            self._private = Path(tempfile.mkdtemp(prefix="hexapod_graph_"))
            self.env["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(private_profile(self._private))
            weakref.finalize(self, shutil.rmtree, self._private, True)
            # Ports of this domain that a node killed in an earlier run left (full: a
            # process that took such an id would hear nothing): gone before anyone does.
            remove_dead_shm(domain_id_from_env(self.env))
        self.procs: dict[str, NodeProcess] = {}
        self._logs: dict[str, IO[bytes]] = {}
        self._started: set[str] = set()
        self._restart_ids = RESTART_PARTICIPANT_IDS
        self._locks: dict[str, list[Path]] = {}
        self._locks_due: dict[str, float] = {}  # monotonic s: next look at a node's locks
        self._fence = PortFence()
        # name -> monotonic s its process was seen dead by a signal (its locks fenced); until
        # a process of that name starts again
        self._killed: dict[str, float] = {}

    def start(self, name: str, *overrides: str, node: str | None = None,
              nice: int | None = None, prefix: Sequence[str] = ()) -> NodeProcess:
        """Start node ``node`` (default ``name``) as process ``name`` with ``-p`` overrides
        (``"stop_at_end:=true"``); ``nice`` defaults to :data:`NICE` of the node; ``prefix``
        is a command to run it under (e.g. ``("chrt", "-f", "10")``: a new interpreter, as
        without ``fork``)."""
        node = node or name
        if node in NODES:
            module, func = NODES[node]
            call_args: tuple[str, ...] = ()
        else:  # a plug-in controller's node (named as the controller): the generic node
            module, func = "hexapod_control.controller_node", "main_controller"
            call_args = (node,)
        nice = NICE.get(node, 0) if nice is None else nice
        ros_args = ["--ros-args"]
        if self.params:
            ros_args += ["--params-file", str(self.params)]
        if self.use_sim_time and node in SIM_TIME_NODES:
            ros_args += ["-p", "use_sim_time:=true"]
        if self.rt_priority and node in RT_PRIORITY_NODES:
            ros_args += ["-p", f"rt_priority:={self.rt_priority}"]
        for o in self.overrides + overrides:
            ros_args += ["-p", o]
        env = self.env
        killed = self._killed.pop(name, None)
        if killed is not None:
            time.sleep(max(0.0, RESTART_PAUSE - (time.monotonic() - killed)))
        if name in self._started and self._private is not None:
            # A restart: a participant id whose shared-memory ports do not exist (not the
            # previous process's, which may have died by SIGKILL: dds_profile.py). First
            # starts keep Fast DDS's own choice: an explicit low id collided with processes
            # that took theirs meanwhile (a test's client made between the Popen and the
            # node's participant; once the sim lost sight of a controller).
            participant = unused_participant_id(domain_id_from_env(self.env),
                                                self._restart_ids)
            if participant is not None:
                self._restart_ids = range(participant + 1, self._restart_ids.stop)
                env = {**env, "FASTRTPS_DEFAULT_PROFILES_FILE":
                       str(private_profile(self._private, participant_id=participant))}
        self._started.add(name)
        log = open(self.log_dir / f"{name}.log", "ab")
        self._logs[name] = log
        if self.fork and not prefix:
            self.procs[name] = node_fork.start(module, func, call_args, ros_args, env,
                                               log.name, nice, name, PRELOAD)
            return self.procs[name]
        call = f"{func}({', '.join(map(repr, call_args))})"
        args = list(prefix) + (["nice", "-n", str(nice)] if nice else [])
        args += [sys.executable, "-c",
                 "import sys; from hexapod_common.runtime.lifeline import die_with_parent; "
                 f"die_with_parent(); from {module} import {func}; sys.exit({call})",
                 *ros_args]
        self.procs[name] = subprocess.Popen(args, stdout=log, stderr=subprocess.STDOUT,
                                            env=env, start_new_session=True)
        return self.procs[name]

    def poll(self, name: str) -> int | None:
        """The exit code of process ``name``, None while it runs. While it runs, notes the
        listener locks of its shared-memory ports; once it has died by a signal (its peers
        drop it when its participant's lease ends: dds_profile.py), holds those locks
        (:meth:`fenced`)."""
        proc = self.procs[name]
        code = proc.poll()
        if code is None:
            now = time.monotonic()
            if now >= self._locks_due.get(name, 0.0):
                # a node's ports are made with its participant, at start: once two looks
                # in a row agree, a look every LOCKS_REFRESH s is enough (one is ~0.5 ms)
                locks = shm_locks(proc.pid)
                if locks and locks == self._locks.get(name):
                    self._locks_due[name] = now + LOCKS_REFRESH
                self._locks[name] = locks or self._locks.get(name, [])
        else:
            self._ended(name, code)
        return code

    def _ended(self, name: str, code: int) -> None:
        if code < 0 and name not in self._killed:  # died by a signal: no goodbye to peers
            self._killed[name] = time.monotonic()
            self._fence.hold(self._locks.get(name, ()))  # keep new participants off its ids
        self._locks.pop(name, None)
        self._locks_due.pop(name, None)

    def fenced(self) -> list[Path]:
        """The listener locks held for nodes of this graph that died by a signal."""
        return self._fence.held

    def log(self, name: str) -> str:
        """The log of process ``name`` so far."""
        return (self.log_dir / f"{name}.log").read_text(errors="replace")

    def wait_for(self, cond: Callable[[], bool], timeout: float, what: str) -> None:
        """Poll ``cond`` until true; raise GraphError naming ``what`` after ``timeout`` s."""
        end = time.monotonic() + timeout
        while not cond():
            if time.monotonic() > end:
                raise GraphError(f"timed out after {timeout:g} s waiting for {what}")
            time.sleep(0.05)

    def wait_log(self, name: str, text: str, timeout: float = 60.0) -> None:
        """Wait until ``text`` appears in the log of ``name``."""
        self.wait_for(lambda: text in self.log(name), timeout, f"'{text}' in {name}'s log")

    def wait_exit(self, name: str, timeout: float) -> int:
        """Wait for process ``name`` to end; its exit code."""
        return self.procs[name].wait(timeout)

    def cpu_seconds(self, name: str) -> float:
        """User + system CPU time used so far by process ``name`` (Linux /proc)."""
        fields = Path(f"/proc/{self.procs[name].pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")

    def rss_mb(self, name: str) -> float:
        """Resident memory of process ``name`` (MB)."""
        for line in Path(f"/proc/{self.procs[name].pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
        return float("nan")

    def stop(self, name: str, timeout: float = 10.0) -> int | None:
        """SIGINT, then SIGTERM, then SIGKILL (each after ``timeout`` s); the exit code."""
        proc = self.procs.get(name)
        if proc is None:
            return None
        self.poll(name)
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
            if proc.poll() is not None:
                break
            try:
                proc.send_signal(sig)
                proc.wait(timeout)
            except subprocess.TimeoutExpired:
                continue
            except ProcessLookupError:
                break
        code = proc.wait()
        self._ended(name, code)
        self._logs.pop(name).close()
        del self.procs[name]
        return code

    def kill(self, name: str, sig: int = signal.SIGKILL) -> int:
        """Send ``sig`` and wait for the end; the exit code."""
        proc = self.procs[name]
        self.poll(name)
        proc.send_signal(sig)
        code = proc.wait(30)
        self._ended(name, code)
        self._logs.pop(name).close()
        del self.procs[name]
        return code

    def stop_all(self, order: Sequence[str] = ()) -> dict[str, int | None]:
        """Stop ``order`` first (in that order), then the rest."""
        codes = {}
        for name in list(order) + [n for n in self.procs if n not in order]:
            if name in self.procs:
                codes[name] = self.stop(name)
        if self._private is not None:
            shutil.rmtree(self._private, ignore_errors=True)
            self._private = None
        self._fence.release(remove=True)  # no sender of this graph is left to use them
        return codes


# --------------------------------------------------------------------------- ROS helpers


def _ros_node(name: str) -> Any:
    import rclpy
    from rclpy.node import Node

    from hexapod_common.runtime.hot_loop import configure_middleware

    configure_middleware(TOOL_PARTICIPANT_IDS)  # not a just-killed node's participant id
    rclpy.init(args=[])
    return Node(f"{name}_{os.getpid()}", start_parameter_services=False)


def _call(node: Any, srv_type: Any, service: str, request: Any, timeout: float,
          missing: str) -> Any:
    import rclpy

    client = node.create_client(srv_type, service)
    if not client.wait_for_service(timeout_sec=timeout):
        raise GraphError(missing)
    future = client.call_async(request)
    rclpy.spin_until_future_complete(node, future, timeout_sec=timeout)
    if not future.done() or future.result() is None:
        raise GraphError(f"{service} did not answer within {timeout:g} s")
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
    """Whether ``controller`` is served by a lifecycle node (an engine controller, or a node
    with a ``get_state`` service); a plain node is switched to as it is.

    Waits up to ``timeout`` for this process to discover the node, then up to 2 s for its
    services (they are announced one by one; ``get_state`` may come after the others)."""
    if controller in engine_names():
        return True
    target = node_of(controller)
    end = time.monotonic() + timeout
    services_by: float | None = None
    while time.monotonic() < end:
        if target in node.get_node_names():
            services_by = services_by or time.monotonic() + 2.0
            try:
                services = node.get_service_names_and_types_by_node(target, "/")
            except Exception:  # noqa: BLE001 - gone meanwhile
                return False
            if any(name == f"/{target}/get_state" for name, _ in services):
                return True
            if time.monotonic() > services_by:
                return False
        time.sleep(0.05)
    return False



def switch(controller: str, timeout: float = 10.0) -> str:
    """Hand control to ``controller`` (see module docstring); the line to print.

    First through the sim's local switch channel (``hexapod_common.core.switch_channel``: no
    ROS context, no discovery, milliseconds); through ROS services if no sim listens there
    or the controller must first be configured and activated."""
    from hexapod_common.core.switch_channel import ChannelError, request

    try:
        answer = request(f"switch {controller}", _domain(), timeout)
    except ChannelError as err:
        raise GraphError(str(err)) from err
    # The sim already told a lifecycle node that is not active apart from a plain node:
    # this process's own discovery of the node's services may take longer than the sim's.
    known_lifecycle = False
    if answer is not None:
        status, _, text = answer.partition(" ")
        if status == "ok":
            return text
        if not text.endswith("not active"):
            raise GraphError(text)
        known_lifecycle = True
    import rclpy
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import GetParameters, SetParameters

    node = _ros_node("hexapod_switch")
    try:
        missing = (f"no hexapod_sim running on ROS_DOMAIN_ID={_domain()} "
                   f"(no /hexapod_sim/set_parameters within {timeout:g} s)")
        current = _call(node, GetParameters, "/hexapod_sim/get_parameters",
                        GetParameters.Request(names=["run.controller"]), timeout,
                        missing).values[0].string_value
        before = (ensure_active(node, controller, timeout)
                  if known_lifecycle or _is_lifecycle(node, controller, timeout)
                  else "active")
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
    """Nodes seen in the graph and the values of one /hexapod/status (None if none came)."""
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
        end = start + timeout
        # until a status came and discovery had DISCOVERY_TIME s to find every node (a node
        # that joined is seen later than the status of the sim that answers at once)
        while (not got or time.monotonic() < start + min(DISCOVERY_TIME, timeout)) \
                and time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=0.1)
        # This process discovers the graph node by node: the status came once the sim was
        # seen, the others may not be yet. The sim's status names what it sees.
        ours = set(node.get_node_names())
        from hexapod_common.runtime.controller_graph import controller_nodes

        controllers = controller_nodes(node)
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    sim = [s for s in statuses(got[-1]) if s.name == "hexapod_sim"] if got else []
    values = dict(sim[0].values) if sim else {}
    theirs = {n for n in values.get("nodes", "").split(",") if n}
    nodes = sorted(n for n in ours | theirs
                   if not n.startswith(("hexapod_status_", "_")))
    if not sim:
        return nodes, None
    # the sim's view (it has long discovered every node) and this tool's
    seen = set(controllers) | set(filter(None, values.get("controller_nodes", "").split(",")))
    nodes = sorted(set(nodes) | seen)
    return nodes, values | {"level": sim[0].level, "message": sim[0].message,
                            "controller_nodes": ",".join(sorted(seen))}


# --------------------------------------------------------------------------- commands


def _cmd_switch(args: argparse.Namespace) -> int:
    print(switch(args.controller, args.timeout))
    return 0


def _cmd_status(args: argparse.Namespace) -> int:
    nodes, st = status(args.timeout)
    if st is None:
        seen = ", ".join(nodes) if nodes else "no nodes"
        print(f"hexapod status: nothing runs on ROS_DOMAIN_ID={_domain()}: no /hexapod/status "
              f"within {args.timeout:g} s ({seen} seen)", file=sys.stderr)
        return 1
    if args.json:
        import json

        print(json.dumps({"nodes": nodes, "status": st}, indent=1))
        return 0
    print(f"nodes: {', '.join(nodes)}")
    print("controllers: " + (", ".join(
        f"{name_of(n)} (node {n}{', in charge' if name_of(n) == st['controller'] else ''})"
        for n in st.get("controller_nodes", "").split(",") if n) or "none on the graph"))
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
    """``python -m hexapod_bringup.cmd_graph switch|status ...``: the same subcommands as
    ``hexapod``, without importing the rest of the CLI (the engine, numba, plots: seconds),
    for scripts/switch_controller.sh. Errors are one line and exit code 2, as in ``hexapod``."""
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


__all__ = ["GraphError", "GraphProcesses", "NODES", "SIM_TIME_NODES", "add_parser",
           "ensure_active", "main", "status", "switch"]


if __name__ == "__main__":
    sys.exit(main())
