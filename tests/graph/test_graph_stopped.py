"""Lockstep waits for the living (R3): with four CPU-bound processes beside the graph, the
controller in charge, the trajectory generator and the recorder are each stopped
(``kill -STOP``) for 3 s and resumed; the run is slower, not different: its bag equals the
engine's run bit for bit, no tick is missed and the run exits 0."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np

from .conftest import fast_params, hexapod_cli, sim_summary
from .test_graph_exits import Script

STOP_S = 3.0
#: s the controller's stop may last beyond STOP_S for `hexapod status` to answer (still
#: well inside the DDS lease, dds_profile.LEASE_S = 5 s)
STATUS_GRACE_S = 1.0
HOGS = 4
DURATION = 8.0
START_S = 1.5


def test_a_stopped_controller_generator_or_recorder_changes_nothing(tmp_path):
    from hexapod_common.core import topics as T
    from hexapod_common.core.layout import O_TH
    from hexapod_control.core.closed_loop import run
    from hexapod_metrics.bag import open_bag, read_joint_state_arrays

    hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"])
            for _ in range(HOGS)]
    # paced at real time at most (same numbers): the run lasts DURATION wall s and more
    # however fast the machine, so the stops, from START_S after tick 0, fall inside it
    s = Script(tmp_path, "--duration", f"{DURATION:g}", "--no-switch", "--controller", "pd_pf",
               "--set", "sim.lockstep_max_rtf=1")
    try:
        s.wait_log("hexapod_sim", "lockstep mode, ", 300)
        time.sleep(START_S)
        pids = s.pids()
        status: list[str] = []
        for name in ("pd_pf_controller", "trajectory_generator", "metrics"):
            asker = None
            os.kill(pids[name], signal.SIGSTOP)
            try:
                if name == "pd_pf_controller":  # what the sim waits for, and how long
                    # asked beside the stop (which lasts STOP_S whatever the answer takes)
                    # once the sim has waited past its first look (LIVENESS_LOOK)
                    time.sleep(1.0)
                    asker = threading.Thread(target=lambda: status.append(
                        hexapod_cli(s.domain, "status").stdout))
                    asker.start()
                    time.sleep(STOP_S - 1.0)
                else:
                    time.sleep(STOP_S)
                if asker is not None:  # a slow answer may take up to a second more
                    asker.join(STATUS_GRACE_S)
            finally:
                os.kill(pids[name], signal.SIGCONT)
            if asker is not None:
                asker.join(120)
        code = s.wait(600)
    finally:
        for h in hogs:
            h.kill()
        s.kill_all()
    assert code == 0, s.stderr()
    status_text = "".join(status)
    assert "s for pd_pf's command of tick" in status_text and "nodes are alive" in status_text, \
        status_text
    summary = sim_summary(s.log("hexapod_sim"))
    ticks = int(round(DURATION / 1e-3))
    assert summary["tick"] == ticks and summary["missed"] == 0, summary
    assert summary["long_waits"] >= 2 and summary["cap_hits"] == 0, summary
    assert summary["longest_wait_s"] >= 0.8 * STOP_S, summary
    assert "going on without waiting" not in s.log("hexapod_sim")
    ref = run(fast_params(), "pd_pf", DURATION)
    with open_bag(s.bag) as b:
        js = read_joint_state_arrays(b, T.JOINT_STATES)
        cmd = read_joint_state_arrays(b, T.JOINT_COMMANDS)
    assert np.array_equal(js.stamps, np.arange(ticks + 1) * 1_000_000)
    assert len(cmd.stamps) == ticks + 1
    assert np.array_equal(js.position.reshape(-1, 6, 2), ref.obs[:, O_TH])
