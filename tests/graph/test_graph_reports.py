"""What the graph tells a user is complete and current: `hexapod status` beside a running
`scripts/run_graph.sh --duration 0` names every node, shows no end tick, warns of a publisher
outside the graph while it is there and stops once it has left; Ctrl-C ends the run with the
indices so far and the bag, and the end summary reports the dropped messages and the
outside publishers.

One run serves every test of this module (real processes: the script, its five nodes, a
rogue node and the `hexapod status` command line); the fixture records what each step saw
and each test asserts one property of it.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from hexapod_common.core import topics as T

from .conftest import hexapod_cli
from .test_graph_exits import Script, table_rows
from .test_graph_join import profile_file

#: One worker runs the module (its module-scoped fixture once): scripts/test.sh uses
#: pytest-xdist's loadgroup distribution.
pytestmark = pytest.mark.xdist_group("test_graph_reports")

HOSTILE = Path(__file__).with_name("hostile_node.py")
NODES = ["hexapod_sim", "metrics", "pd_p_controller", "pd_pf_controller",
         "trajectory_generator"]
ROGUE = "/rogue_node"


def _status(s: Script, *args: str) -> subprocess.CompletedProcess:
    r = hexapod_cli(s.domain, "status", "--timeout", "60", *args)
    assert r.returncode == 0, r.stderr
    return r


def _status_json(s: Script) -> dict:
    return json.loads(_status(s, "--json").stdout)


@pytest.fixture(scope="module")
def seen(tmp_path_factory):
    """Run the scenario once; what each step saw."""
    tmp = tmp_path_factory.mktemp("reports")
    # A long lockstep timeout (as test_graph_hostile.py): on a loaded 2-core machine, with
    # the rogue's flood beside it, a starved controller can take more than the default
    # 0.5 s to answer; a missed tick (a 'mixed' cycle) or a fallback (exit 7) would then be
    # the machine's doing, not what these tests look at. Paced at a quarter of real time: the
    # steps wait for wall-clock things (status polls, the rogue's coming and going), and an
    # unpaced graph would spend both cores meanwhile.
    s = Script(tmp, "--duration", "0", "--no-switch", "--controller", "pd_p",
               "--set", "sim.lockstep_timeout=20.0", "--set", "sim.lockstep_max_rtf=0.25")
    out: dict = {}
    rogue = None
    try:
        s.wait_log("hexapod_sim", "lockstep mode")
        out["text"] = _status(s).stdout
        out["json"] = _status_json(s)
        # A rogue on the domain with the run's DDS profile (it read the join line, it has
        # no key): its commands reach the sim and are dropped, it is named while it is
        # there. (One without the profile is kept out by the run's partition unheard:
        # test_graph_hostile.py.)
        log = open(tmp / "rogue.log", "wb")
        env = {**os.environ, "ROS_DOMAIN_ID": str(s.domain),
               "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
               "FASTRTPS_DEFAULT_PROFILES_FILE": profile_file(s)}
        rogue = subprocess.Popen([sys.executable, str(HOSTILE), "rogue", "--out",
                                  str(tmp / "rogue.json"), "--name", ROGUE[1:]],
                                 env=env, stdout=log, stderr=subprocess.STDOUT,
                                 start_new_session=True)
        s.wait_log("hexapod_sim", f"publishers on {T.JOINT_COMMANDS} that are not nodes of "
                   f"this graph: {ROGUE}", timeout=120)
        out["with_rogue"] = _status_json(s)
        rogue.send_signal(signal.SIGTERM)
        assert rogue.wait(30) == 0
        rogue = None
        # Gone: the status stops naming it (the guard looks every 2 s while one is there;
        # drops count as recent for 5 s).
        end = time.monotonic() + 90
        after = _status_json(s)
        while (after["status"]["level"] != "ok" or ROGUE in after["status"]["outside_publishers"]
               ) and time.monotonic() < end:
            time.sleep(1.0)
            after = _status_json(s)
        out["rogue_gone"] = after
        out["rogue_gone_text"] = _status(s).stdout
        s.wait_log("metrics", "cycle 1 [1, 2] s")
        os.kill(s.proc.pid, signal.SIGINT)
        out["code"] = s.wait()
        out["stdout"], out["stderr"] = s.stdout(), s.stderr()
        out["bag"] = s.bag
    finally:
        if rogue is not None:
            rogue.kill()
            rogue.wait()
        s.kill_all()
    return out


def test_status_names_every_running_node(seen):
    lines = seen["text"].splitlines()
    nodes = [line for line in lines if line.startswith("nodes: ")]
    assert nodes, seen["text"]
    assert [n for n in nodes[0][len("nodes: "):].split(", ")] == NODES
    assert seen["json"]["nodes"] == NODES


def test_status_of_a_run_without_duration_shows_no_end_tick(seen):
    assert seen["json"]["status"]["end_tick"] == "none"
    tick = seen["text"].split("(tick ")[1].split(")")[0]
    assert tick.endswith("; runs until stopped") and " of " not in tick, seen["text"]


def test_status_warns_of_an_outside_publisher_only_while_it_is_there(seen):
    st = seen["with_rogue"]["status"]
    assert st["level"] == "warn" and ROGUE in st["outside_publishers"], st
    assert f"publishers outside the graph: {T.JOINT_COMMANDS}: {ROGUE}" in st["message"]
    gone = seen["rogue_gone"]["status"]
    assert gone["level"] == "ok" and gone["outside_publishers"] == "none", gone
    assert ROGUE in gone["outside_publishers_left"] and int(gone["dropped"]) > 0
    assert "publishers outside the graph:" not in gone["message"]
    assert "WARN" not in seen["rogue_gone_text"] and ROGUE not in seen["rogue_gone"]["nodes"]


def test_ctrl_c_prints_the_indices_so_far_and_the_bag(seen):
    out, bag = seen["stdout"], seen["bag"]
    assert seen["code"] == 0, (seen["stderr"], out)  # --duration 0: Ctrl-C: normal end
    rows = table_rows(out)
    assert rows and rows[0].split()[0] == "pd_p", out
    assert f"bag: {bag}" in out
    assert (bag / "indices.json").exists() and (bag / "metadata.yaml").exists()


def test_end_summary_reports_dropped_messages_and_outside_publishers(seen):
    assert seen["code"] == 0, (seen["stderr"], seen["stdout"])
    out = seen["stdout"].splitlines()
    dropped = [line for line in out if line.startswith("  inputs: dropped sim ")]
    assert dropped and f"{T.JOINT_COMMANDS} (unauthenticated)" in dropped[0], out
    outside = [line for line in out if line.startswith("  publishers outside the graph: ")]
    assert outside and f"{T.JOINT_COMMANDS}: {ROGUE}" in outside[0], out
