"""Fixtures of the node-graph tests: real node processes, one ROS_DOMAIN_ID per graph.

Every graph gets its own domain id (1..101, from the pid and a counter), localhost-only
discovery, and its processes are always stopped at teardown (SIGINT, SIGTERM, SIGKILL).
Tests wait on conditions (log lines, process exits, files), never on fixed sleeps.
"""
from __future__ import annotations

import contextlib
import itertools
import os
import re
import subprocess
import sys
from pathlib import Path
from typing import Any, Callable, Iterator

import pytest

from hexapod_bringup.cmd_graph import GraphProcesses

rclpy = pytest.importorskip("rclpy", reason="the graph tests need rclpy (scripts/setup.sh)")

_counter = itertools.count()
#: Graph tests check behaviour (ticks, switches, recording, failures), not the paper's
#: numbers: they run at model.md's original 1e-4 s physics and 1 kHz control unless a test
#: overrides these (later overrides win), which keeps lockstep runs and bags small. The
#: lockstep wait for a command is 5 s, not 0.5: the suite runs graphs side by side on two
#: workers, where a node can stall past 0.5 s; a test of the timeout sets its own.
FAST_TIMING = ("sim.dt:=0.0001", "sim.control_period:=0.001")
#: Everything but the recorder stops first, so that the recorder gets their last messages.
STOP_ORDER = ("hexapod_sim", "trajectory_generator", "pd_p_controller", "pd_pf_controller",
              "metrics")


def fast_params(**overrides: Any) -> Any:
    """The params file's parameters at :data:`FAST_TIMING` (what make_graph's nodes run)."""
    from hexapod_common.core.params import load_params

    return load_params(**{"sim.dt": 1e-4, "sim.control_period": 1e-3, **overrides})


def domain_range() -> tuple[int, int]:
    """The ROS_DOMAIN_IDs this session's graphs may take: HEXAPOD_TEST_DOMAINS="LO-HI"
    (inclusive; default 1-100), so that test sessions of two checkouts on one machine can be
    kept apart."""
    spec = os.environ.get("HEXAPOD_TEST_DOMAINS", "1-100")
    try:
        lo, hi = (int(v) for v in spec.split("-"))
    except ValueError:
        raise SystemExit(f"HEXAPOD_TEST_DOMAINS={spec!r} is invalid: give LO-HI, "
                         "e.g. 1-100") from None
    if not 0 <= lo <= hi <= 232:
        raise SystemExit(f"HEXAPOD_TEST_DOMAINS={spec!r} is invalid: allowed 0 <= LO <= HI "
                         "<= 232")
    return lo, hi


def next_domain_id() -> int:
    """A ROS_DOMAIN_ID of :func:`domain_range` unlikely to be used by a concurrent test
    session, and never by another worker of this one (pytest-xdist: worker w of n takes the
    ids = lo + w mod n)."""
    lo, hi = domain_range()
    worker = os.environ.get("PYTEST_XDIST_WORKER", "gw0")[2:]
    w = int(worker) if worker.isdigit() else 0
    n = max(1, int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")))
    session = os.getppid() if n > 1 else os.getpid()  # the workers' common parent
    slot = (session * 13 + next(_counter) * 7) % max(1, (hi - lo + 1) // n)
    return lo + slot * n + w


def _graphs(tmp: Path) -> Iterator[Callable[..., GraphProcesses]]:
    graphs: list[GraphProcesses] = []

    def make(name: str = "g", **kw: Any) -> GraphProcesses:
        kw["overrides"] = FAST_TIMING + tuple(kw.get("overrides", ()))
        domain = next_domain_id()
        g = GraphProcesses(tmp / f"{name}_logs",
                           env={"ROS_DOMAIN_ID": str(domain),
                                "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}, **kw)
        g.domain_id = domain  # type: ignore[attr-defined]
        graphs.append(g)
        return g

    yield make
    for g in graphs:
        g.stop_all(order=STOP_ORDER)


@pytest.fixture
def make_graph(tmp_path: Path) -> Iterator[Callable[..., GraphProcesses]]:
    """``make_graph(name)`` -> a GraphProcesses on a fresh domain id; all stopped at teardown."""
    yield from _graphs(tmp_path)


@pytest.fixture(scope="module")
def make_module_graph(tmp_path_factory: pytest.TempPathFactory
                      ) -> Iterator[Callable[..., GraphProcesses]]:
    """As :func:`make_graph`, for a module-scoped fixture: one run whose outputs several
    tests read (each asserting one property) instead of one run per test."""
    yield from _graphs(tmp_path_factory.mktemp("graph"))


def sim_summary(log: str) -> dict[str, float]:
    """Figures of the sim's final summary line."""
    m = re.search(r"stopped at tick (\d+) .*?: (\d+) missed, (\d+) late, (\d+) on time.*?"
                  r"(\d+) switches \((\d+) missed within", log)
    assert m, f"no summary line in the sim's log:\n{log[-2000:]}"
    keys = ("tick", "missed", "late", "on_time", "switches", "missed_after_switch")
    out: dict[str, float] = dict(zip(keys, (int(x) for x in m.groups())))
    held = re.search(r"(\d+) holds for the recorder \(([\d.]+) s\)", log[m.start():])
    assert held, log[m.start():]
    out["recorder_holds"], out["recorder_held_s"] = int(held[1]), float(held[2])
    waits = re.search(r"(\d+) long waits for a living controller \(longest ([\d.]+) s; "
                      r"(\d+) at the cap\)", log[m.start():])
    if waits:
        out["long_waits"], out["longest_wait_s"] = int(waits[1]), float(waits[2])
        out["cap_hits"] = int(waits[3])
    return out


#: The nodes of a recorded single-controller run (what the sim waits for before tick 0).
RECORDED_RUN = ("trajectory_generator", "pd_pf_controller", "metrics")


def start_recorded_run(g: GraphProcesses, bag: Path, duration: float,
                       also_wait_for: tuple[str, ...] = ()) -> None:
    """Recorder (into ``bag``), trajectory generator, PD-P&F and a sim that stops after
    ``duration`` simulated s (tick 0 once those and ``also_wait_for``'s nodes are there)."""
    g.start("metrics", f"bag_path:={bag}")
    g.start("trajectory_generator")
    g.start("pd_pf_controller")
    g.start("hexapod_sim", "stop_at_end:=true", f"run.duration:={duration}",
            f"wait_for:={','.join(RECORDED_RUN + also_wait_for)}")


def finish_recorded_run(g: GraphProcesses, timeout: float) -> dict[str, float]:
    """Wait for the sim of :func:`start_recorded_run` to stop at the end (exit 0), stop the
    others (the recorder last) and return the sim's summary."""
    assert g.wait_exit("hexapod_sim", timeout) == 0, g.log("hexapod_sim")
    summary = sim_summary(g.log("hexapod_sim"))
    g.stop_all(order=RECORDED_RUN)
    return summary


def hexapod_cli(domain_id: int, *args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    """Run the ``hexapod`` CLI on a domain id."""
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id),
           "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    return subprocess.run([sys.executable, "-m", "hexapod_bringup.cli", *args], env=env,
                          capture_output=True, text=True, timeout=timeout)


#: The name of :func:`ros_client`'s node (one per test process; each test has its domain).
CLIENT_NODE = f"graph_test_{os.getpid()}"


@contextlib.contextmanager
def ros_client(domain_id: int) -> Iterator[Any]:
    """An rclpy node on ``domain_id`` in this process (own context), destroyed afterwards."""
    from rclpy.context import Context

    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain_id)
    node = rclpy.create_node(CLIENT_NODE, context=ctx,
                             start_parameter_services=False)
    try:
        yield node
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)


def call(node: Any, srv_type: Any, name: str, request: Any, timeout: float = 30) -> Any:
    """Call a service from ``node`` (own executor) and return the response."""
    from rclpy.executors import SingleThreadedExecutor

    client = node.create_client(srv_type, name)
    assert client.wait_for_service(timeout_sec=timeout), f"{name} not available"
    future = client.call_async(request)
    ex = SingleThreadedExecutor(context=node.context)
    ex.add_node(node)
    ex.spin_until_future_complete(future, timeout_sec=timeout)
    ex.remove_node(node)
    assert future.done(), f"{name} did not answer"
    return future.result()
