"""`hexapod status` and `hexapod switch` answer from the sim's local channel, without a ROS
context of their own (what made them take seconds: rclpy's start, DDS discovery, service
matching; the times are scripts/bench_startup.py --cli's, docs/benchmarks.md)."""
from __future__ import annotations

import os
import subprocess
import sys

from .conftest import call, next_domain_id, ros_client
from .test_graph_exits import ROOT

#: Runs the `hexapod` CLI in a process where importing rclpy fails: every answer must come
#: without a ROS context.
NO_ROS = ("import sys; sys.modules['rclpy'] = None; from hexapod_bringup.cli import main; "
          "sys.exit(main(sys.argv[1:]))")


def no_ros_cli(domain_id: int, *args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id)}
    return subprocess.run([sys.executable, "-c", NO_ROS, *args], env=env, capture_output=True,
                          text=True, timeout=60)


def lean_cli(domain_id: int, *args: str) -> subprocess.CompletedProcess:
    """`scripts/hexapod ARGS` from a shell that has not sourced scripts/env.sh."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("VIRTUAL_ENV", "PYTHONPATH", "LD_LIBRARY_PATH", "AMENT_PREFIX_PATH",
                        "_ROS_WHEELS_BOOTSTRAP_COMPLETE", "COLCON_PREFIX_PATH")}
    env["ROS_DOMAIN_ID"] = str(domain_id)
    return subprocess.run([str(ROOT / "scripts" / "hexapod"), *args], env=env,
                          capture_output=True, text=True, timeout=60)


def one_line(r: subprocess.CompletedProcess) -> str:
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and not r.stdout and len(lines) == 1, (r.returncode, r.stdout,
                                                                    r.stderr)
    return lines[0]


def test_status_and_switch_answer_without_a_ros_context(make_graph):
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState

    g = make_graph()
    for n in ("trajectory_generator", "pd_p_controller", "pd_pf_controller"):
        g.start(n)
    # tick 0 waits for a controller node that is not there: status says so meanwhile
    g.start("hexapod_sim", "startup_timeout:=600",
            "wait_for:=trajectory_generator,pd_p_controller,pd_pf_controller,latecomer")
    g.wait_log("hexapod_sim", "waiting for trajectory_generator", timeout=120)
    r = no_ros_cli(g.domain_id, "status")
    assert r.returncode == 0, r.stderr
    assert "WARN: waiting for the graph (not there yet: " in r.stdout, r.stdout
    assert "node latecomer" in r.stdout.split("not there yet: ")[1], r.stdout
    g.stop("hexapod_sim")

    g.start("hexapod_sim", "wait_for:=trajectory_generator,pd_p_controller,pd_pf_controller")
    g.wait_log("hexapod_sim", "lockstep mode", timeout=120)
    r = no_ros_cli(g.domain_id, "status")
    assert r.returncode == 0, r.stderr
    assert "nodes: hexapod_sim, pd_p_controller, pd_pf_controller, trajectory_generator\n" \
        in r.stdout, r.stdout
    assert ("controllers: pd_p (node pd_p_controller, active), pd_pf (node pd_pf_controller, "
            "active, in charge)\n") in r.stdout, r.stdout

    # the sim activates an inactive lifecycle controller itself (its change_state service)
    with ros_client(g.domain_id) as client:
        req = ChangeState.Request()
        req.transition.id = Transition.TRANSITION_DEACTIVATE
        assert call(client, ChangeState, "/pd_p_controller/change_state", req).success
    r = no_ros_cli(g.domain_id, "switch", "pd_p")
    assert r.returncode == 0, r.stderr
    assert r.stdout == ("switching pd_pf -> pd_p at the next tick; pd_p_controller was "
                        "inactive, now active\n")
    g.wait_log("hexapod_sim", "switched pd_pf -> pd_p at tick")

    # scripts/hexapod from a plain shell: the venv's Python on the sources, no env.sh
    r = lean_cli(g.domain_id, "switch", "pd_pf")
    assert r.returncode == 0 and r.stdout == "switching pd_p -> pd_pf at the next tick\n", r
    r = lean_cli(g.domain_id, "status", "--json")
    assert r.returncode == 0 and '"controller": "pd_pf"' in r.stdout, r


def test_without_a_graph_status_and_switch_fail_at_once_in_one_line():
    domain = next_domain_id()
    for args in (("status",), ("switch", "pd_p")):
        line = one_line(no_ros_cli(domain, *args))
        assert line == (f"hexapod {args[0]}: error: nothing runs on ROS_DOMAIN_ID={domain}: "
                        "no sim, no ROS node"), line
        assert one_line(lean_cli(domain, *args)) == line


def test_without_the_sims_channel_the_tools_look_over_ros(make_graph):
    """ROS nodes on the domain but no sim's channel: the tools look over ROS (a lean start
    re-executes itself through scripts/env.sh for rclpy), for a bounded time, then say so."""
    g = make_graph()
    g.start("pd_p_controller")
    g.wait_log("pd_p_controller", "active: answering", timeout=120)
    line = one_line(lean_cli(g.domain_id, "switch", "pd_p"))
    assert "no hexapod_sim running on ROS_DOMAIN_ID=" in line, line
    r = lean_cli(g.domain_id, "status")
    assert r.returncode == 1 and "no switch channel and no /hexapod/status" in r.stderr, r
