"""Nodes forked from the pre-imported fork server (hexapod_common.runtime.node_fork): they
get what ``subprocess.Popen`` gives a node (command line, environment, log, session,
niceness, working directory), a Popen-like handle, and they die with their launcher."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from hexapod_common.runtime import node_fork


def _start(target: str, *args: str, log: Path, nice: int = 0, name: str = "fork_test"
           ) -> node_fork.ForkedNode:
    env = {**os.environ, "FORK_TEST": "seen"}
    return node_fork.start("fork_target", target, args, ["--ros-args", "-p", "a:=1"], env,
                           str(log), nice, name, preload=())


def test_a_forked_node_runs_with_its_own_command_line_environment_log_and_session(tmp_path):
    out, log = tmp_path / "out.json", tmp_path / "node.log"
    log.write_text("before\n")
    p = _start("report", str(out), log=log, nice=5, name="a_long_node_name_here")
    assert p.wait(60) == 3 and p.returncode == 3 and p.poll() == 3
    seen = json.loads(out.read_text())
    assert seen["argv"] == ["-c", "--ros-args", "-p", "a:=1"]
    assert seen["env"] == "seen" and seen["pid"] == p.pid == seen["sid"]  # own session
    assert seen["nice"] == os.nice(0) + 5 and seen["cwd"] == os.getcwd()
    assert seen["name"] == "a_long_node_nam"  # the kernel keeps 15 characters
    # ps -f and pgrep -f: the node's name, not the fork server's command line
    assert seen["cmdline"].rstrip("\0") == "a_long_node_name_here"
    assert log.read_text().splitlines() == ["before", "on stdout", "on stderr"]  # appended


def test_wait_times_out_and_a_signal_gives_popens_exit_code(tmp_path):
    flag = tmp_path / "flag"
    p = _start("wait_for_term", str(flag), log=tmp_path / "node.log",
               name=f"fork_wait_{os.getpid()}")
    with pytest.raises(subprocess.TimeoutExpired):
        p.wait(0.2)
    end = time.monotonic() + 30  # until the node has set its title (a busy machine)
    while True:
        found = subprocess.run(["pgrep", "-f", f"fork_wait_{os.getpid()}"],
                               capture_output=True, text=True)
        if found.stdout.split() or time.monotonic() > end:
            break
        time.sleep(0.05)
    assert found.stdout.split() == [str(p.pid)], found
    assert p.poll() is None and p.returncode is None
    p.kill()
    assert p.wait(30) == -signal.SIGKILL
    p.kill()  # ended: nothing to signal, no error


LAUNCHER = textwrap.dedent("""
    import os, sys, time
    sys.path.insert(0, sys.argv[2])
    from hexapod_common.runtime import node_fork
    p = node_fork.start("fork_target", "wait_for_term", [sys.argv[1]], [], dict(os.environ),
                        sys.argv[1] + ".log", 0, "orphan_test", preload=())
    print(p.pid, flush=True)
    time.sleep(600)
""")


def test_a_forked_node_gets_sigterm_when_its_launcher_is_killed(tmp_path):
    flag = tmp_path / "flag"
    launcher = subprocess.Popen([sys.executable, "-c", LAUNCHER, str(flag),
                                 str(Path(__file__).parent)], stdout=subprocess.PIPE,
                                text=True)
    try:
        pid = int(launcher.stdout.readline())  # type: ignore[union-attr]
        end = time.monotonic() + 60
        while not Path(f"{flag}.ready").exists() and time.monotonic() < end:
            time.sleep(0.05)
        assert Path(f"{flag}.ready").read_text() == str(pid)
        launcher.kill()
        launcher.wait(30)
        end = time.monotonic() + 30
        while not flag.exists() and time.monotonic() < end:
            time.sleep(0.05)
        assert flag.read_text() == "term"  # the node stopped as on SIGTERM, not orphaned
    finally:
        if launcher.poll() is None:
            launcher.kill()
            launcher.wait()


def test_the_fork_server_imports_no_ros_and_starts_no_thread():
    """What the launcher's fork server preloads (cmd_graph.PRELOAD) must not import rclpy:
    Fast DDS starts threads at load, which a forked node would lack."""
    code = textwrap.dedent("""
        import importlib, os, sys
        from hexapod_bringup.cmd_graph import PRELOAD
        before = len(os.listdir("/proc/self/task"))
        for m in PRELOAD:
            importlib.import_module(m)
        print("rclpy" in sys.modules, len(os.listdir("/proc/self/task")) - before)
    """)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=120, env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["False", "0"], r.stdout
