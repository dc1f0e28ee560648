"""runtime/liveness.py: a stopped process is alive, an ended one (even unreaped) is not; a
node the launcher did not start is judged by the graph's node list."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys

from hexapod_common.runtime.liveness import Liveness, launcher_pids, process_alive


def test_a_stopped_process_is_alive_and_an_ended_unreaped_one_is_not():
    p = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        assert process_alive(p.pid)
        os.kill(p.pid, signal.SIGSTOP)
        assert process_alive(p.pid)
        os.kill(p.pid, signal.SIGKILL)
        os.waitid(os.P_PID, p.pid, os.WEXITED | os.WNOWAIT)  # a zombie: ended, not reaped
        assert not process_alive(p.pid)
    finally:
        p.kill()
        p.wait()
    assert not process_alive(p.pid)


def test_a_node_lives_while_on_the_graph_and_a_launcher_node_dies_with_its_process(tmp_path):
    path = tmp_path / "pids.json"
    graph = {"stranger", "pd_pf_controller", "gone"}
    asked = []

    def nodes() -> set[str]:
        asked.append(1)
        return graph

    live = Liveness(nodes, str(path))
    assert live.alive("pd_pf_controller", "stranger")  # no file yet: by the graph alone
    path.write_text(json.dumps({"pd_pf_controller": os.getpid(), "gone": 2 ** 22 + 12345}))
    assert live.alive("pd_pf_controller", "stranger")
    n = len(asked)
    assert not live.alive("gone")  # its process ended: known without the graph
    assert len(asked) == n
    assert not live.alive("pd_pf_controller", "nobody")
    graph.clear()  # their leases ran out (stopped for longer than a lease): they have left
    assert not live.alive("stranger") and not live.alive("pd_pf_controller")


def test_an_unreadable_pids_file_leaves_every_node_to_the_graph(tmp_path):
    path = tmp_path / "pids.json"
    for text in ("", "{", "[1, 2]", json.dumps({"a": "12", "b": True, "c": 7})):
        path.write_text(text)
        pids = launcher_pids(str(path))
        assert pids == ({"c": 7} if text.startswith('{"a"') else {})
    assert launcher_pids(str(tmp_path / "missing.json")) == {}
    assert Liveness(lambda: ["x"], str(path)).alive("x")
