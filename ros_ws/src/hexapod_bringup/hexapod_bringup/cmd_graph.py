"""The node graph's process launcher: :class:`GraphProcesses`.

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

import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import weakref
from pathlib import Path
from typing import IO, Callable, Sequence

from hexapod_common.runtime.dds_profile import (LEASE_S, RESTART_PARTICIPANT_IDS, PortFence,
                                                domain_id_from_env, shm_locks,
                                                private_profile, remove_dead_shm,
                                                run_partition, unused_participant_id)
from hexapod_common.runtime import node_fork
from hexapod_common.runtime.lifeline import PARENT_ENV

from .graph_cli import GraphError

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
            self.env["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(private_profile(
                self._private, partition=run_partition(self.env)))
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
                       str(private_profile(self._private, participant_id=participant,
                                           partition=run_partition(env)))}
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


__all__ = ["GraphError", "GraphProcesses", "NODES", "PRELOAD", "RT_NODES", "RT_PRIORITY_NODES",
           "SIM_TIME_NODES"]
