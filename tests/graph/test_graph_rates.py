"""The lockstep graph at the paper experiments' control rate (control at every physics step)
records exactly what the in-process closed loop computes."""
from __future__ import annotations

import numpy as np

from hexapod_control.core.closed_loop import run
from hexapod_metrics.bag import open_bag, read_joint_state_arrays
from hexapod_common.core import topics as T
from hexapod_common.core.params import load_params

from .conftest import finish_recorded_run, start_recorded_run

DURATION = 1.0
PERIOD = 1e-4  # 10 kHz, the paper experiments' rate
DT = 5e-5      # and their physics step (the params file's defaults)


def test_lockstep_graph_equals_the_engine_at_10_khz_control(make_graph, tmp_path):
    bag = tmp_path / "bag"
    # a generous lockstep timeout: this test checks equality, not latency under CI load
    g = make_graph(overrides=(f"sim.dt:={DT}", f"sim.control_period:={PERIOD}",
                              "sim.lockstep_timeout:=5.0"))
    start_recorded_run(g, bag, DURATION)
    summary = finish_recorded_run(g, 600)
    assert summary["missed"] == 0 and summary["late"] == 0

    p = load_params(**{"sim.dt": DT, "sim.control_period": PERIOD})
    assert p.substeps == 2
    ref = run(p, "pd_pf", DURATION)
    n = ref.obs.shape[0]
    assert n == 10001
    with open_bag(bag) as b:
        cols = {}
        for topic in T.STATE_TOPICS:
            a = read_joint_state_arrays(b, topic)
            assert np.array_equal(a.stamps, np.arange(n) * 100_000), f"{topic}: a tick is missing"
            cols[topic] = (a.position, a.velocity, a.effort)
        np.testing.assert_allclose(T.obs_from_columns(cols), ref.obs, rtol=0, atol=1e-9)
        cmd = read_joint_state_arrays(b, T.JOINT_COMMANDS)
        np.testing.assert_allclose(cmd.effort[:n - 1].reshape(-1, 6, 2), ref.command,
                                   rtol=0, atol=1e-9)
