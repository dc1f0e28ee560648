"""The impact torque (C4's deciding number) converges in dt where the run does; touchdowns
are the gait's, one per stance phase even if the foot bounces."""
import math

import numpy as np
import pytest

from hexapod_bringup.core import claims
from hexapod_bringup.core.convergence import refined
from hexapod_bringup.core.simulate import simulate, window_ticks
from hexapod_common.core.layout import O_FP, O_TQ, OBS_SHAPE
from hexapod_common.core.params import load_params
from hexapod_metrics.core.impacts import impact_torque, low_pass, touchdown_ticks


def _impact(p, controller):
    sim = simulate(p, controller)
    k_a, k_b = window_ticks(p, p.run.duration)
    t_t = p.cycle_time * (1.0 - p.gait.duty_factor)
    return impact_torque(sim.run.obs, sim.run.reference.support, p.sim.control_period, t_t,
                         k_a, k_b)


@pytest.mark.parametrize("controller", ["pd_p", "pd_pf"])
def test_impact_torque_converges_in_dt_at_ideal_actuators_on_hard_ground(controller):
    """T_max = inf, ground 150 %: dt, dt/2, dt/4 at the same 10 kHz control. PD-P: all three
    within 1 %; PD-P&F: dt/2 -> dt/4 within 1 % (model.md's criterion; dt -> dt/2 moves
    ~5 %). (On 300 % ground and above PD-P&F's whole torque history moves 2-40 % with dt,
    every windowed measure tried with it; those points stay undecided.)"""
    p = load_params(**{"actuator.t_max": math.inf, "ground.scale": 1.5})
    runs = [_impact(refined(p, f), controller) for f in (1, 2, 4)]
    peaks = np.array([r.peak for r in runs])
    assert all(r.count == 6 for r in runs)  # one touchdown per leg in the last cycle
    assert abs(peaks[1] - peaks[2]) < 0.01 * peaks[2]
    if controller == "pd_p":
        assert np.ptp(peaks) < 0.01 * peaks[2]


def test_touchdowns_are_one_per_stance_phase_even_when_the_foot_bounces():
    n = 400
    support = np.zeros((n, 6), dtype=bool)
    support[100:200, 0] = True
    support[300:, 0] = True
    y = np.full((n, 6), 0.05)
    y[103:110, 0] = -0.001   # lands 3 ticks late ...
    y[112:200, 0] = -0.001   # ... bounces and lands again: still one touchdown
    y[295:, 0] = -0.001      # lands 5 ticks early (within half a transfer)
    assert touchdown_ticks(y, support, 40, 0, n) == [(0, 103), (0, 295)]
    assert touchdown_ticks(y, support, 40, 150, n) == [(0, 295)]


def test_peak_and_impulse_of_a_planted_torque_spike():
    n, dt = 1000, 1e-4
    obs = np.zeros((n,) + OBS_SHAPE)
    obs[:, O_FP, :, 1] = 0.05
    support = np.zeros((n, 6), dtype=bool)
    support[500:, 2] = True
    obs[500:, O_FP, 2, 1] = -0.001
    obs[:, O_TQ, 2, 0] = 100.0
    obs[510:520, O_TQ, 2, 1] = -900.0   # a 1 ms spike of 900 N m at the knee, 1 ms after
    r = impact_torque(obs, support, dt, 0.01, 0, n)
    assert r.count == 1 and r.peak == 900.0
    fast = np.abs(obs[:, O_TQ] - low_pass(obs[:, O_TQ], dt, 0.02))[501:701, 2]
    assert r.impulse == pytest.approx(fast.sum() * dt)
    # the spike's 0.9 N m s above the low-pass, then the low-pass's own excursion decaying
    # below the signal (~0.5 N m s within the window): |x - LP(x)| counts a spike ~twice
    assert 1.3 < r.impulse < 1.45
    x = np.ones((50, 1))
    assert np.all(low_pass(x, dt, 0.01) == 1.0)


def test_c4_is_decided_by_the_impact_torque_when_given():
    def m(v):
        return claims.Measured(v, v, v, True)

    def pt(scale=1.0):
        return {n: m(0.01 * scale) for n in ("eps_xH", "eps_yH", "eps_xF", "eps_yF", "T_L")}

    calm = {1.0: {"pd_p": pt(), "pd_pf": pt()}, 3.0: {"pd_p": pt(), "pd_pf": pt()}}
    wild_steps = {3.0: {"pd_p": claims.Measured(100.0, 90.0, 110.0, True),
                        "pd_pf": claims.Measured(3000.0, 2500.0, 4000.0, False)}}
    assert claims.c4(calm, wild_steps).status == "undecided"
    big = {3.0: {"pd_p": m(500.0), "pd_pf": m(1300.0)}}
    v = claims.c4(calm, wild_steps, big)
    assert v.status == "holds" and "is x2.6 PD-P's at 300 %" in v.evidence
    assert "not deciding" in v.evidence
    small = {3.0: {"pd_p": m(500.0), "pd_pf": m(600.0)}}
    assert claims.c4(calm, wild_steps, small).status == "fails"
