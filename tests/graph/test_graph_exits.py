"""scripts/run_graph.sh end to end: honest exit codes, Ctrl-C, kill -9, settings that hold.

Each test runs the real script (the Python launcher behind it, real node processes) on its
own ROS_DOMAIN_ID and waits on conditions (log lines, files, process exits).
"""
from __future__ import annotations

import json
import os
import re
import signal
import stat
import subprocess
import time
from pathlib import Path
from typing import Any, Callable

import pytest
import numpy as np

from hexapod_bringup.graph_launcher import EXIT_CODES

from .conftest import call, hexapod_cli, next_domain_id, ros_client, sim_summary

ROOT = Path(__file__).resolve().parents[2]
#: conftest.FAST_TIMING as run_graph.sh options (behaviour, not the paper's numbers)
FAST = ("--set", "sim.dt=0.0001", "--control-rate", "1000")
#: wall s a recorder stays stopped at most, waiting for the sim to hold a tick for it
HOLD_WAIT_S = 3.5


class Script:
    """scripts/run_graph.sh running in its own session, output in files."""

    def __init__(self, tmp: Path, *args: str, bag: Path | None = None,
                 fast: bool = True) -> None:
        self.domain = next_domain_id()
        self.bag = bag or tmp / "bag"
        self.logs = Path(f"{self.bag}_logs")
        self.out = tmp / "stdout.txt"
        self.err = tmp / "stderr.txt"
        env = {**os.environ, "ROS_DOMAIN_ID": str(self.domain),
               "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
        with self.out.open("w") as out, self.err.open("w") as err:
            self.proc = subprocess.Popen(
                [str(ROOT / "scripts" / "run_graph.sh"), "--bag", str(self.bag),
                 *(FAST if fast else ()), *args],
                stdout=out, stderr=err, env=env, start_new_session=True)

    def log(self, name: str) -> str:
        try:
            return (self.logs / f"{name}.log").read_text(errors="replace")
        except OSError:
            return ""

    def wait_for(self, cond: Callable[[], bool], timeout: float, what: str) -> None:
        end = time.monotonic() + timeout
        while not cond():
            assert self.proc.poll() is None or cond(), (
                f"run_graph ended ({self.proc.returncode}) before {what}:\n{self.stderr()}")
            assert time.monotonic() < end, f"timed out waiting for {what}:\n{self.stderr()}"
            time.sleep(0.05)

    def wait_log(self, name: str, text: str, timeout: float = 120) -> None:
        self.wait_for(lambda: text in self.log(name), timeout, f"'{text}' in {name}.log")

    def pids(self) -> dict[str, int]:
        """The launcher's node pids, once the sim is among them (the file is written
        before the sim starts too: the sim reads it)."""
        def read() -> dict[str, int]:
            try:
                return json.loads((self.logs / "pids.json").read_text())
            except (OSError, ValueError):
                return {}
        self.wait_for(lambda: "hexapod_sim" in read(), 60, "pids.json with the sim")
        return read()

    def wait(self, timeout: float = 180) -> int:
        return self.proc.wait(timeout)

    def stdout(self) -> str:
        return self.out.read_text()

    def stderr(self) -> str:
        return self.err.read_text()

    def kill_all(self) -> None:
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait()
        try:
            pids = json.loads((self.logs / "pids.json").read_text())
        except (OSError, ValueError):
            return
        for pid in pids.values():
            with_pid(pid, lambda p: os.kill(p, signal.SIGKILL))


def with_pid(pid: int, action: Callable[[int], Any]) -> None:
    try:
        action(pid)
    except (ProcessLookupError, PermissionError):
        pass


def alive(pid: int) -> bool:
    """True if ``pid`` runs (and is not a zombie)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


@pytest.fixture
def script(tmp_path: Path):
    started: list[Script] = []

    def start(*args: str) -> Script:
        s = Script(tmp_path, *args)
        started.append(s)
        return s

    yield start
    for s in started:
        s.kill_all()


def table_rows(stdout: str) -> list[str]:
    """The indices table's rows (first word = the label; not the '^' notes under a row)."""
    lines = stdout.splitlines()
    i = next(i for i, line in enumerate(lines) if line.startswith("indices per controller"))
    return [line.strip() for line in lines[i + 2:]
            if line.startswith("  ") and not line.strip().startswith("^")]


def test_default_scenario_exits_0_with_both_controllers_segments(script):
    s = script("--duration", "3")
    assert s.wait() == 0, s.stderr()
    rows = table_rows(s.stdout())
    assert [r.split()[0] for r in rows] == ["pd_pf", "pd_p"], s.stdout()
    assert "0 missed" in s.stdout() and f"bag: {s.bag}" in s.stdout()
    assert (s.bag / "indices.json").exists()


def test_the_default_graph_records_the_default_simulate_motion(tmp_path):
    # One default scenario (the params file's): `scripts/run_graph.sh --no-switch
    # --duration 3` records the joint motion of `hexapod simulate --controller pd_pf
    # --duration 3` (its own numbers, the engine's run), every tick, to 1e-9 rad.
    from hexapod_control.core.closed_loop import run
    from hexapod_common.core import topics as T
    from hexapod_common.core.params import load_params
    from hexapod_metrics.bag import open_bag, read_joint_state_arrays

    # a loaded machine (the suite's other graphs beside it) once starved the trajectory
    # generator for the default 0.5 s lockstep timeout: ticks missed, then a fallback (as
    # getting-started.md says); the timeout does not change the numbers
    s = Script(tmp_path, "--no-switch", "--duration", "3", "--set", "sim.lockstep_timeout=5",
               fast=False)
    try:
        assert s.wait(600) == 0, s.stderr()
    finally:
        s.kill_all()
    assert "control at 10 kHz" in s.stdout(), s.stdout()
    ref = run(load_params(), "pd_pf", 3.0)
    with open_bag(s.bag) as b:
        js = read_joint_state_arrays(b, T.JOINT_STATES)
    n = ref.obs.shape[0]
    assert np.array_equal(js.stamps, np.arange(n) * 100_000)
    from hexapod_common.core.layout import O_TH

    recorded = js.position.reshape(-1, 6, 2)
    assert np.abs(recorded - ref.obs[:, O_TH]).max() <= 1e-9


def test_lockstep_waits_for_a_stopped_recorder_and_its_bag_lacks_nothing(script):
    # The recorder is stopped (SIGSTOP) mid-run until the sim says it holds a tick for it
    # (the recorder RECORDER_LAG ticks behind: how soon depends on the machine's speed), at
    # most HOLD_WAIT_S; the sim goes on when it resumes, and the bag has every tick of every
    # per-tick topic (run_graph compares, exit 4 if not). Well inside the participants'
    # lease (dds_profile.LEASE_S = 5 s), past which a stopped process is dropped as dead.
    from hexapod_common.core import topics as T
    from hexapod_metrics.bag import open_bag, read_joint_state_arrays

    s = script("--duration", "10", "--no-switch", "--controller", "pd_pf")
    s.wait_log("metrics", "cycle 0 [0, 1] s")
    pid = s.pids()["metrics"]
    os.kill(pid, signal.SIGSTOP)
    stopped = time.monotonic()
    try:
        while (left := HOLD_WAIT_S - (time.monotonic() - stopped)) > 0:
            try:
                if "for the recorder" in hexapod_cli(s.domain, "status", timeout=left).stdout:
                    break
            except subprocess.TimeoutExpired:
                break
    finally:
        os.kill(pid, signal.SIGCONT)
    assert s.wait() == 0, s.stderr()
    summary = sim_summary(s.log("hexapod_sim"))
    assert summary["tick"] == 10_000 and summary["missed"] == 0
    assert summary["recorder_holds"] >= 1 and summary["recorder_held_s"] >= 0.1, summary
    assert "going on without waiting" not in s.log("hexapod_sim")
    assert f"{summary['recorder_holds']} holds for the recorder" in s.stdout()  # the report
    with open_bag(s.bag) as b:
        for topic in (T.JOINT_STATES, T.FOOT_FORCES, T.HIP_STATES, T.JOINT_COMMANDS):
            js = read_joint_state_arrays(b, topic)
            assert np.array_equal(js.stamps, np.arange(10_001) * 1_000_000), topic


def test_killed_controller_exits_3_and_fallback_cycles_are_not_the_controllers(script):
    s = script("--duration", "4", "--no-switch", "--controller", "pd_pf")
    s.wait_log("metrics", "cycle 0 [0, 1] s")
    os.kill(s.pids()["pd_pf_controller"], signal.SIGKILL)
    code = s.wait()
    err, out = s.stderr(), s.stdout()
    assert code == EXIT_CODES["node died"] == 3, err
    assert "pd_pf_controller was killed by SIGKILL during the run" in err
    assert "fallback (exit 7)" in err  # the fallback is reported too
    assert_uncommanded_cycles_are_labelled(s, "pd_pf")
    assert f"bag: {s.bag}" in out


def assert_uncommanded_cycles_are_labelled(s: Script, controller: str) -> None:
    """Cycles with ticks the controller did not command carry another label, in
    indices.json and in the printed table; clean cycles keep the controller's name. (Under
    load the first ticks may go unanswered too: that cycle is then 'mixed', rightly.)"""
    doc = json.loads((s.bag / "indices.json").read_text())
    cycles = doc["cycles"]
    assert any(c["uncommanded_ticks"] > 0 for c in cycles), cycles
    for c in cycles:
        assert (c["label"] == controller) == (c["uncommanded_ticks"] == 0), c
    # The table's row is the per-cycle mean over the cycles the controller commanded
    # entirely, and names them; with none, it names the last cycle's label and no numbers.
    seg = doc["segments"][-1]
    row = table_rows(s.stdout())[-1]
    own = seg["mean_cycles"]
    by_number = {c["cycle"]: c for c in cycles}
    if own:
        assert row.startswith(controller + " "), row
        assert all(by_number[k]["uncommanded_ticks"] == 0 for k in own), (own, cycles)
        span = f"{len(own)}: {own[0]}-{own[-1]}" if len(own) > 1 else f"1: {own[0]}"
        assert f" {span} " in row, row
        assert len(own) < len(seg["cycles"])  # the fallback's cycles are left out
    else:
        last = seg["last_full_cycle"]
        assert row.startswith(last["label"] + " "), row  # 'mixed(pd_pf+376 uncommanded) ...'
        assert "no cycle commanded entirely" in row, row
    # The bag says the same: `hexapod analyze` labels each cycle as the metrics node did
    # online (its /hexapod/indices records in the bag) and as indices.json.
    from hexapod_metrics.core.analysis import analyze_bag

    a = analyze_bag(s.bag)
    offline = {c.cycle: (c.controller, c.uncommanded) for c in a.cycles if c.sums is not None}
    assert offline == {c["cycle"]: (c["label"], c["uncommanded_ticks"]) for c in cycles}
    assert {c: label for c, label, _ in a.online} == {c: v[0] for c, v in offline.items()}
    assert any(label != controller for label, _ in offline.values())


def test_fallback_alone_exits_7(script, tmp_path):
    # the controller in charge is deactivated (not killed): no node dies, the sim falls back
    s = script("--duration", "6", "--no-switch", "--controller", "pd_p")
    s.wait_log("metrics", "cycle 0 [0, 1] s")
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState

    with ros_client(s.domain) as node:
        req = ChangeState.Request()
        req.transition.id = Transition.TRANSITION_DEACTIVATE
        assert call(node, ChangeState, "/pd_p_controller/change_state", req).success
    code = s.wait()
    assert code == EXIT_CODES["fallback"] == 7, s.stderr()
    assert "fallback (exit 7)" in s.stderr() and "node died" not in s.stderr()
    assert_uncommanded_cycles_are_labelled(s, "pd_p")
    # under joint damping the body sinks through the ground: those cycles are not a walk,
    # and nothing prints their numbers as indices (walking.py)
    assert "fallen (exit 8)" in s.stderr()
    cycles = json.loads((s.bag / "indices.json").read_text())["cycles"]
    fell = [c for c in cycles if c.get("fallen")]
    assert fell and all(c["indices"] is None and c["label"] != "pd_p" for c in fell)
    assert cycles[0]["indices"] is not None and not cycles[0].get("fallen")
    row = table_rows(s.stdout())[-1]
    assert row.startswith("pd_p "), row  # its clean cycles' mean (spans: above)
    assert re.search(r"\^ \d+ other cycles of this segment fallen \(no indices\), the first: "
                     r"cycle \d+ \((fallback|mixed\(pd_p\+\d+ uncommanded\))\): "
                     r"hip height", s.stdout()), s.stdout()
    # the transition a ROS tool made is in the bag: the controller's status says it, at once
    from hexapod_common.core import cdr
    from hexapod_metrics.bag import open_bag
    from hexapod_common.core import topics as T

    states = []
    with open_bag(s.bag) as b:
        for _, t, data in b.messages([T.STATUS]):
            states += [(t, dict(st.values).get("lifecycle")) for st in
                       cdr.decode_diagnostic_array(bytes(data))[1] if st.name == "pd_p_controller"]
    labels = [lc for _, lc in states]
    assert "active" in labels and "inactive" in labels[labels.index("active"):], states


def test_killed_recorder_exits_4_and_stops_the_graph(script):
    s = script("--duration", "0")
    s.wait_log("hexapod_sim", "lockstep mode")
    pids = s.pids()
    os.kill(pids["metrics"], signal.SIGKILL)
    code = s.wait()
    assert code == EXIT_CODES["recorder failed"] == 4, s.stderr()
    assert "the recorder (metrics) was killed by SIGKILL during the run" in s.stderr()
    assert "stopping the graph" in s.stderr()
    assert f"bag: {s.bag}" in s.stdout()
    assert not any(alive(p) for n, p in pids.items() if n != "launcher")


def test_the_launcher_says_what_the_bag_lacks_of_the_sims_ticks(tmp_path):
    """The report compares the bag's per-tick messages (the recorder's counts in
    indices.json) with the sim's ticks (the last tick's may be missing after an interrupted
    run), and says what the recorder counted as lost on the way (holes in the senders'
    sequences, msg_auth.Verifier.missing); a complete bag says nothing. (A lockstep run with
    the control path under SCHED_FIFO lost ~20000 of 120000 messages to a starved recorder
    this way, unnoticed before.)"""
    from hexapod_bringup.graph_launcher import bag_shortfall

    indices = tmp_path / "indices.json"
    per_tick = ("/hexapod/joint_states", "/hexapod/foot_forces", "/hexapod/hip_states")

    def doc(counts, lost=None):
        indices.write_text(json.dumps({"messages": dict(zip(per_tick, counts)),
                                       "recording": {"lost_in_transit": lost or {}}}))
        return indices

    done = {"tick": 4000, "started": True, "finished": True}
    assert bag_shortfall(done, doc((4001, 4001, 4001))) == ("", "")
    assert bag_shortfall(done, doc((4001, 2000, 4001), {"/hexapod/foot_forces": 2001})) == (
        "/hexapod/foot_forces 2000 of 4001", "/hexapod/foot_forces 2001")
    assert bag_shortfall(done, doc((3000, 3000, 3000)))[0] == (  # the tail never came
        "/hexapod/joint_states 3000 of 4001, /hexapod/foot_forces 3000 of 4001, "
        "/hexapod/hip_states 3000 of 4001")
    interrupted = {**done, "finished": False}
    assert bag_shortfall(interrupted, doc((4000, 4000, 4000))) == ("", "")
    assert bag_shortfall(interrupted, doc((3999, 4000, 4000)))[0] == (
        "/hexapod/joint_states 3999 of 4000")
    assert bag_shortfall(done, doc((4001, 4001, 4001), {"/hexapod/reference": 7})) == (
        "", "/hexapod/reference 7")
    assert bag_shortfall(None, doc((1, 1, 1))) == ("", "")
    assert bag_shortfall({**done, "started": False}, doc((0, 0, 0))) == ("", "")
    assert bag_shortfall(done, tmp_path / "missing.json") == ("", "")


def test_ctrl_c_before_the_end_of_a_timed_run_exits_130(script):
    s = script("--duration", "60", "--no-switch")
    s.wait_log("metrics", "cycle 0 [0, 1] s")
    os.kill(s.proc.pid, signal.SIGINT)
    assert s.wait() == EXIT_CODES["interrupted"] == 130
    assert f"bag: {s.bag}" in s.stdout() and table_rows(s.stdout())


def test_kill_9_of_the_launcher_leaves_no_node_running(script):
    s = script("--duration", "0")
    s.wait_log("hexapod_sim", "lockstep mode")
    pids = s.pids()
    nodes = {n: p for n, p in pids.items() if n != "launcher"}
    assert len(nodes) == 5 and all(alive(p) for p in nodes.values())
    assert pids["launcher"] == s.proc.pid  # run_graph.sh execs the launcher
    os.kill(s.proc.pid, signal.SIGKILL)
    s.proc.wait()
    end = time.monotonic() + 60
    while any(alive(p) for p in nodes.values()) and time.monotonic() < end:
        time.sleep(0.1)
    assert not [n for n, p in nodes.items() if alive(p)]
    # they stopped as on SIGTERM: the recorder closed its bag
    assert (s.bag / "metadata.yaml").exists() and (s.bag / "indices.json").exists()


def test_a_killed_idle_controller_leaves_the_graph_within_its_lease(make_graph):
    # SIGKILL says no goodbye: the others keep the participant until its lease (the graph's
    # profile, dds_profile.py) runs out; the lockstep run goes on without a missed tick.
    # The transport's clean-up of the dead process's ports stalls every process ~1 s on a
    # loaded 2-core machine (docs/getting-started.md): the wait for a command is 5 s here, so
    # that stall is not a miss while a controller that stopped answering still would be.
    g = make_graph()
    for n in ("trajectory_generator", "pd_p_controller", "pd_pf_controller"):
        g.start(n)
    g.start("hexapod_sim", "wait_for:=trajectory_generator,pd_p_controller,pd_pf_controller",
            "run.duration:=6.0", "stop_at_end:=true", "sim.lockstep_timeout:=5.0")
    g.wait_log("hexapod_sim", "lockstep mode", timeout=120)
    with ros_client(g.domain_id) as node:
        end = time.monotonic() + 60
        while "pd_p_controller" not in node.get_node_names() and time.monotonic() < end:
            time.sleep(0.05)
        g.kill("pd_p_controller")  # pd_pf is in charge: pd_p is idle
        killed = time.monotonic()
        while "pd_p_controller" in node.get_node_names() and time.monotonic() < killed + 15:
            time.sleep(0.02)
        gone = time.monotonic() - killed
        assert "pd_p_controller" not in node.get_node_names(), (
            f"still in the graph {gone:.1f} s after the kill")
    assert g.wait_exit("hexapod_sim", 600) == 0
    summary = sim_summary(g.log("hexapod_sim"))
    assert summary["missed"] == 0 and "0 fallback episodes" in g.log("hexapod_sim")


def test_fast_dds_profile_is_private_to_the_graph(make_graph, tmp_path):
    import tempfile

    planted = Path(tempfile.gettempdir()) / "hexapod_fastdds_planted_by_someone.xml"
    g = make_graph()
    path = Path(g.env["FASTRTPS_DEFAULT_PROFILES_FILE"])
    assert path != planted and path.read_text().count("127.0.0.1") == 1
    assert stat.S_IMODE(path.parent.stat().st_mode) == 0o700
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    g.stop_all()
    assert not path.exists()


def test_settings_on_the_running_graph_take_effect_or_are_refused(make_graph):
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters

    g = make_graph()
    for n in ("trajectory_generator", "pd_p_controller", "pd_pf_controller"):
        g.start(n)
    g.start("hexapod_sim", "wait_for:=trajectory_generator,pd_p_controller,pd_pf_controller")
    g.wait_log("hexapod_sim", "lockstep mode", timeout=120)

    def pv(v: object) -> ParameterValue:
        if isinstance(v, str):
            return ParameterValue(type=ParameterType.PARAMETER_STRING, string_value=v)
        return ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=float(v))

    with ros_client(g.domain_id) as node:
        def set_one(target: str, name: str, v: object):
            req = SetParameters.Request(parameters=[Parameter(name=name, value=pv(v))])
            return call(node, SetParameters, f"/{target}/set_parameters", req).results[0]

        # node parameters read once at start are read-only
        for name, v in (("switch_at", 1.0), ("switch_to", "pd_p"), ("stop_at_end", "x"),
                        ("wait_for", ""), ("startup_timeout", 5.0)):
            r = set_one("hexapod_sim", name, v)
            assert not r.successful and "read-only" in r.reason, (name, r.reason)
        r = set_one("trajectory_generator", "lookahead", 3.0)
        assert not r.successful and "read-only" in r.reason
        # a parameter set on a node that does not use it is refused, not ignored
        r = set_one("pd_pf_controller", "ground.k_y", 5.0)
        assert not r.successful
        r = set_one("pd_pf_controller", "pd_p.kp1", 5.0)
        assert not r.successful
        r = set_one("hexapod_sim", "pd_pf.kp1", 5.0)
        assert not r.successful
        r = set_one("pd_pf_controller", "pd_pf.kp1", 21000.0)  # its own gain: taken live
        assert r.successful
        # run.controller on the sim goes through the same liveness check as `switch`
        req = ChangeState.Request()
        req.transition.id = Transition.TRANSITION_DEACTIVATE
        assert call(node, ChangeState, "/pd_p_controller/change_state", req).success
        end = time.monotonic() + 30
        while True:
            r = set_one("hexapod_sim", "run.controller", "pd_p")
            if not r.successful or time.monotonic() > end:
                break
            time.sleep(0.1)  # the graph may still show the old subscription
        assert not r.successful
        assert "pd_p_controller is not active" in r.reason, r.reason
    assert g.procs["hexapod_sim"].poll() is None
    assert "switched" not in g.log("hexapod_sim")
    sw = hexapod_cli(g.domain_id, "switch", "pd_p")  # activates it, then hands over
    assert sw.returncode == 0, sw.stderr
    assert "switching pd_pf -> pd_p" in sw.stdout and "was inactive, now active" in sw.stdout
    g.wait_log("hexapod_sim", "switched pd_pf -> pd_p", timeout=60)


@pytest.fixture
def small_disk(tmp_path: Path):
    """A 3 MB tmpfs (root only: mount); unmounted afterwards."""
    mnt = tmp_path / "small"
    mnt.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=3m", "tmpfs", str(mnt)],
                       capture_output=True, text=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a small tmpfs to fill (needs root): {r.stderr.strip()}")
    yield mnt
    subprocess.run(["umount", "-l", str(mnt)], capture_output=True)


def test_full_disk_exits_5_and_stops_the_graph(small_disk, tmp_path):
    s = Script(tmp_path, "--duration", "6", bag=small_disk / "bag")
    try:
        code = s.wait()
    finally:
        s.kill_all()
    err = s.stderr()
    assert code == EXIT_CODES["disk full"] == 5, err
    assert "disk full (exit 5): the recorder ran out of disk space" in err
    assert f"bag: {s.bag}" in s.stdout()


@pytest.mark.parametrize("node", ["hexapod_sim", "pd_pf_controller", "metrics"])
@pytest.mark.parametrize("edit, message", [
    (("k_y: 1000000.0", "k_yy: 1000000.0"),
     "parameter 'ground.k_yy' = 1000000.0 is invalid: allowed a known parameter name (did you "
     "mean 'ground.k_y'?)"),
    (("    ground:", "    grond:"), "unknown group 'grond' (did you mean 'ground'?)"),
])
def test_node_started_by_hand_refuses_a_misspelt_params_file(make_graph, tmp_path, node, edit,
                                                             message):
    from hexapod_common.core.params import default_params_path

    f = tmp_path / "typo.yaml"
    f.write_text(default_params_path().read_text().replace(*edit))
    g = make_graph(params=str(f))
    g.start(node, f"bag_path:={tmp_path / 'bag'}" if node == "metrics" else "wait_for:=''")
    assert g.wait_exit(node, 120) == 2
    log = g.log(node)
    assert message in log and "Traceback" not in log
    assert len([line for line in log.splitlines() if "ERROR" in line]) == 1


@pytest.mark.parametrize("node, arg, message", [
    ("markers", "rate:=0.0", "parameter 'rate' = 0.0 is invalid: allowed float in (0, 1e+06]"),
    ("markers", "deliver_to:=5", "parameter 'deliver_to' = 5 is invalid: allowed any str"),
    ("markers", "startup_timeout:=-1.0", "parameter 'startup_timeout' = -1.0 is invalid"),
    ("metrics", "reorder_window:=-0.5", "parameter 'reorder_window' = -0.5 is invalid"),
    ("trajectory_generator", "lookahead:=-2", "parameter 'lookahead' = -2 is invalid"),
    ("trajectory_generator", "publish_interval:=-0.1",
     "parameter 'publish_interval' = -0.1 is invalid: allowed float in [0, 1]"),
    ("hexapod_sim", "switch_to:=pd_x", "parameter 'switch_to' = 'pd_x' is invalid"),
    ("foxglove_bridge", "port:=70000", "parameter 'port' = 70000 is invalid"),
])
def test_node_started_by_hand_refuses_a_bad_node_parameter(make_graph, tmp_path, node, arg,
                                                           message):
    """`ros2 run <pkg> <node> --ros-args -p name:=value` with a value outside the node's
    table: one ERROR line naming it, exit 2, no traceback."""
    g = make_graph()
    extra = [f"bag_path:={tmp_path / 'bag'}"] if node == "metrics" else []
    g.start(node, arg, *extra)
    assert g.wait_exit(node, 120) == 2
    log = g.log(node)
    assert message in log and "Traceback" not in log, log
    assert len([line for line in log.splitlines() if "ERROR" in line]) == 1, log
