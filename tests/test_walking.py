"""A walk or not (hexapod_metrics.core.walking): a cycle whose hips leave the band around
H_B, whose feet sink, or whose body does not move forward has no indices; runs, batches,
bags and the command line say ``fallen``."""
from __future__ import annotations

import json
import subprocess
from dataclasses import replace

import numpy as np
from hexapod_bringup.core.simulate import evaluate_batch, simulate
from hexapod_common.core.params import load_params
from hexapod_control.core.closed_loop import Case
from hexapod_metrics.core.indices import window_sums
from hexapod_metrics.core.walking import HIP_BAND, MAX_DEPTH, MIN_PROGRESS, not_walking

P = load_params(**{"sim.control_period": 0.001})


def _walk(n: int = 1001, hip_dy: float = 0.0, foot_y: float = 0.0,
          speed: float = 1.0) -> object:
    """Sums of a synthetic window: hips at H_B + hip_dy walking at ``speed`` x V_F."""
    t = np.arange(n) * 1e-3
    hip = np.zeros((n, 6, 2))
    hip[:, :, 0] = speed * P.gait.velocity * t[:, None]
    hip[:, :, 1] = P.gait.body_height + hip_dy
    foot = np.zeros((n, 6, 2))
    foot[:, :, 1] = foot_y
    z = np.zeros((n, 6, 2))
    return window_sums(z, z, z, hip, hip, foot, foot, 1e-3)


def test_each_check_of_a_walk():
    assert not_walking(_walk(), P) is None
    h_b = P.gait.body_height
    assert not_walking(_walk(hip_dy=0.9 * HIP_BAND * h_b), P) is None
    assert "hip height" in not_walking(_walk(hip_dy=1.1 * HIP_BAND * h_b), P)
    assert "hip height" in not_walking(_walk(hip_dy=-1.1 * HIP_BAND * h_b), P)
    assert not_walking(_walk(foot_y=-0.9 * MAX_DEPTH), P) is None
    assert "below the ground" in not_walking(_walk(foot_y=-1.1 * MAX_DEPTH), P)
    assert not_walking(_walk(speed=1.1 * MIN_PROGRESS), P) is None
    assert "walked" in not_walking(_walk(speed=0.9 * MIN_PROGRESS), P)
    assert "walked" in not_walking(_walk(speed=-1.0), P)
    assert "walked" in not_walking(_walk(speed=1.6), P)
    # the checks hold over windows added up: a fall in either half is a fall of the whole
    fell = _walk(hip_dy=-0.5)
    assert not_walking(_walk() + fell, P) and not_walking(fell + _walk(), P)


def test_a_collapse_under_low_saturation_is_fallen_in_run_and_batch_alike():
    """T_max 100 N m: the hexapod cannot carry itself and sinks through the ground (hip y
    < 0) in cycle 1; its numbers are not indices of a walk, single run and batch agree."""
    p = P.with_values(**{"actuator.t_max": 100.0})
    single = simulate(p, "pd_pf", 3.0).outcome
    batch, ok = evaluate_batch([Case(p, "pd_pf"), Case(P, "pd_pf")], 3.0)
    assert single.status == batch.status == "fallen" and single.indices is None
    assert "hip height" in single.reason and "gait cycle 2" in single.reason
    assert [c is None for c in single.cycles] == [c is None for c in batch.cycles]
    assert single.cycles[2] is None
    assert ok.status == "ok" and all(c is not None for c in ok.cycles)
    assert simulate(P, "pd_pf", 3.0).outcome == replace(ok, case=ok.case)


def _hexapod(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["scripts/hexapod", *args], capture_output=True, text=True,
                          timeout=300)


def test_the_command_line_says_fallen_and_exits_8(tmp_path):
    args = ("--controller", "pd_pf", "--set", "sim.control_period=0.001",
            "--t-max", "100", "--duration", "3")
    r = _hexapod("simulate", *args, "--json")
    assert r.returncode == 8, r.stderr
    doc = json.loads(r.stdout)["pd_pf"]
    assert doc["status"] == "fallen" and doc["indices"] is None and "hip" in doc["reason"]
    assert doc["cycles"][2] == {"cycle": 2, "t_a": 2.0, "t_b": 3.0, "status": "fallen"}
    r = _hexapod("simulate", *args, "--bag", str(tmp_path / "bag"))
    assert r.returncode == 8 and "fallen" in r.stdout and "E_av" in r.stdout
    assert "e+" not in r.stdout.split("E_av", 1)[1].splitlines()[0]  # no number for E_av
    r = _hexapod("analyze", "--cycles", "--no-plots", str(tmp_path / "bag"))
    assert r.returncode == 8, r.stderr
    assert "no indices, cycle 1: fallen: hip height" in r.stdout
