"""Real-time scheduling of the control path (``rt_priority``, hexapod_common/runtime/rt_sched.py).

In a realtime graph started with ``rt_priority`` the sim's, the controllers' and the
trajectory generator's main threads and Fast DDS receive and event threads run under
SCHED_FIFO (both controllers at the priority, in charge or not), the
recorder's Fast DDS threads too (not its main thread), nothing else; a node that may not
use SCHED_FIFO says so in one warning and runs on with normal scheduling.
"""
from __future__ import annotations

import os
import shutil
import time

import pytest

from hexapod_common.runtime.rt_sched import control_path_threads, realtime_permitted

from .conftest import sim_summary

ALL = "trajectory_generator,pd_p_controller,pd_pf_controller,metrics"
PRIORITY = 20


def _policies(pid: int) -> dict[str, tuple[int, int]]:
    """(policy, priority) of the main thread and the Fast DDS threads of process ``pid``."""
    return {name: (os.sched_getscheduler(tid), os.sched_getparam(tid).sched_priority)
            for tid, name in control_path_threads(pid)}


def _others(pid: int) -> list[int]:
    """Policies of the threads of ``pid`` that are neither its main thread nor Fast DDS's
    receive and event threads."""
    path = {tid for tid, _ in control_path_threads(pid)}
    return [os.sched_getscheduler(int(t)) for t in os.listdir(f"/proc/{pid}/task")
            if int(t) not in path]


@pytest.mark.realtime
@pytest.mark.skipif(not realtime_permitted(PRIORITY), reason="SCHED_FIFO not permitted here")
def test_realtime_graph_runs_its_control_path_under_sched_fifo(make_graph, tmp_path):
    g = make_graph(overrides=("sim.mode:=realtime",), rt_priority=PRIORITY)
    g.start("metrics", f"bag_path:={tmp_path / 'bag'}")
    for node in ("trajectory_generator", "pd_p_controller", "pd_pf_controller"):
        g.start(node)
    g.start("hexapod_sim", "stop_at_end:=true", "run.duration:=6.0", f"wait_for:={ALL}")
    g.wait_log("hexapod_sim", "realtime mode", timeout=120)
    # States have named pd_pf for a while (not the recorder's "cycle 0" line: its main
    # thread has normal scheduling, and on a machine the graph keeps busy it comes late).
    time.sleep(2.0)
    assert g.procs["hexapod_sim"].poll() is None, g.log("hexapod_sim")
    fifo = os.SCHED_FIFO
    expected = {"hexapod_sim": PRIORITY, "pd_pf_controller": PRIORITY,  # in charge
                "pd_p_controller": PRIORITY,  # idle
                "trajectory_generator": PRIORITY}
    for name, prio in expected.items():
        threads = _policies(g.procs[name].pid)
        assert "main" in threads and any(t.startswith("dds.shm.") for t in threads), threads
        assert any(t.startswith("dds.ev.") for t in threads), threads
        assert all(p == (fifo, prio) for p in threads.values()), (name, threads)
        assert f"rt_priority {PRIORITY}: SCHED_FIFO for main, dds." in g.log(name)
    # The recorder: its Fast DDS threads, not the main one.
    for name in ("metrics",):
        pid = g.procs[name].pid
        threads = _policies(pid)
        assert all(p == (fifo, PRIORITY) for t, p in threads.items() if t != "main"), threads
        assert os.sched_getscheduler(pid) == os.SCHED_OTHER
        assert f"rt_priority {PRIORITY}: SCHED_FIFO for dds." in g.log(name)
    # Every other thread keeps normal scheduling (the shared-memory watchdog, UDP receive
    # threads, Python's own).
    for name in g.procs:
        others = _others(g.procs[name].pid)
        assert others and all(p == os.SCHED_OTHER for p in others), (name, others)
    assert g.wait_exit("hexapod_sim", 120) == 0, g.log("hexapod_sim")
    assert sim_summary(g.log("hexapod_sim"))["tick"] == 6000


@pytest.mark.skipif(shutil.which("setpriv") is None, reason="needs setpriv (util-linux)")
def test_a_node_without_the_privilege_warns_once_and_runs_normally(make_graph):
    g = make_graph(rt_priority=PRIORITY)
    # setpriv drops CAP_SYS_NICE from the node's process (as for an ordinary user).
    g.start("pd_p_controller", prefix=("setpriv", "--bounding-set", "-sys_nice"))
    g.wait_log("pd_p_controller", "active: answering", timeout=120)
    log = g.log("pd_p_controller")
    warnings = [x for x in log.splitlines() if "not applied" in x]
    assert len(warnings) == 1, log
    assert (f"rt_priority {PRIORITY} not applied: SCHED_FIFO priority {PRIORITY} refused "
            f"(Operation not permitted): needs CAP_SYS_NICE or an rtprio limit") in warnings[0]
    assert "running with normal scheduling" in warnings[0]
    assert all(p[0] == os.SCHED_OTHER
               for p in _policies(g.procs["pd_p_controller"].pid).values())
    assert g.stop("pd_p_controller") == 0
    assert "Traceback" not in g.log("pd_p_controller")
