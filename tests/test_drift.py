"""The window-independent indices beside eq. (11) (indices.py, "Drift and tracking"): the
drift speeds drift_xH, drift_xF and the detrended horizontal errors trk_xH, trk_xF are the
same in cycle 10 and cycle 20 of a long run, where eps_xH and eps_xF keep growing; they are
dt-converged (trk by the rule; the drift speeds at first order, and the drift per cycle, a
length, within 1 mm); and eq. (11a, c)'s term of each leg is sqrt(offset^2 + tracking^2),
on made-up samples and on a real run."""
from __future__ import annotations

import numpy as np
import pytest
from hexapod_bringup.core.convergence import Convergence, refined, tolerance
from hexapod_bringup.core.simulate import evaluate_batch
from hexapod_common.core.params import load_params
from hexapod_control.core.closed_loop import Case
from hexapod_metrics.core.indices import DRIFT_NAMES, window_sums

DURATION = 21.0  # cycles 0..20
CONTROLLERS = ("pd_p", "pd_pf")


@pytest.fixture(scope="module")
def long_runs():
    """Each controller on the base case at dt, 21 s, then at dt, dt/2, dt/4 and dt/8, 11 s."""
    p = load_params()
    long = evaluate_batch([Case(p, c) for c in CONTROLLERS], DURATION)
    cases = [Case(refined(p, f), c) for c in CONTROLLERS for f in (1, 2, 4, 8)]
    outs = evaluate_batch(cases, 11.0)
    return {c: (long[i], outs[4 * i:4 * i + 4]) for i, c in enumerate(CONTROLLERS)}


@pytest.mark.parametrize("controller", CONTROLLERS)
def test_drift_indices_are_stationary_where_the_paper_errors_grow(long_runs, controller):
    cycles = long_runs[controller][0].cycles
    assert len(cycles) == 21
    c10, c20 = cycles[10], cycles[20]
    for name in DRIFT_NAMES:
        a, b = getattr(c10, name), getattr(c20, name)
        assert abs(a - b) < tolerance(name, b), (name, a, b)
    # the paper's horizontal errors do not stay put: the offset grows by the drift
    assert c20.eps_xH > 1.5 * c10.eps_xH and c20.eps_xF > 1.5 * c10.eps_xF
    # the hips' drift per cycle is V_F T - L (their reference is x = V_F t)
    p = load_params()
    assert c20.drift_xH * p.cycle_time == pytest.approx(
        p.gait.velocity * p.cycle_time - c20.L, abs=1e-9)
    assert c20.drift_xH > 0  # the body falls behind on the base case, both controllers


@pytest.mark.parametrize("controller", CONTROLLERS)
def test_drift_indices_are_dt_converged(long_runs, controller):
    """trk_xH and trk_xF converge by the rule (dt/2 -> dt/4). The drift speeds converge at
    about first order in dt (each halving of dt shrinks their change), about 1 % per
    halving from dt/4 on, which is not the rule's "< 1 % from dt/2 to dt/4":
    what the report decides on them is their band over dt..dt/8, which stays far narrower
    than the gap between the controllers (docs/indices.md)."""
    runs = long_runs[controller][1]
    for cycle in (2, 10):
        at = [_at_cycle(o, cycle) for o in runs]
        cv = Convergence(tuple(at[:3]))
        for name in ("trk_xH", "trk_xF"):
            assert cv.index_converged(name), (cycle, name, [getattr(r, name) for r in cv.runs])
        for name in ("drift_xH", "drift_xF"):
            vals = [getattr(o.indices, name) for o in at]
            steps = np.abs(np.diff(vals))
            assert steps[2] < steps[1] < steps[0], vals
            assert steps[2] < 0.015 * abs(vals[3]), vals


@pytest.mark.parametrize("controller", CONTROLLERS)
def test_the_drift_per_cycle_is_a_length_within_1_mm_in_time_and_in_dt(long_runs, controller):
    """The drift per gait cycle d_x = drift_x T (m; V_F T - L for the hips) is a length, so
    the project's rule for lengths applies: cycle 10 and cycle 20 within 1 mm (they are
    within 1 % too), and dt/2 -> dt/4 within 1 mm. What holds honestly: the whole d_x is
    about 1 mm, so the 1 mm bound is loose; relative to its size d_x moves about 1 % per
    halving of dt (first order), which test_drift_indices_are_dt_converged pins down."""
    period = load_params().cycle_time
    long, refined_runs = long_runs[controller]
    for name in ("drift_xH", "drift_xF"):
        d10, d20 = (getattr(long.cycles[k], name) * period for k in (10, 20))
        assert abs(d10 - d20) < 1e-3 and abs(d10 - d20) < 0.01 * abs(d20), (name, d10, d20)
        d = [getattr(o.cycles[10], name) * period for o in refined_runs]  # dt .. dt/8
        assert abs(d[1] - d[2]) < 1e-3, (name, d)
        assert 0.5e-3 < d[2] < 2e-3, (name, d)  # about a millimetre per cycle, behind


@pytest.mark.parametrize("controller", CONTROLLERS)
def test_a_real_runs_eps_x_per_leg_is_its_offset_and_detrended_error_in_quadrature(
        controller):
    """On a real run (base case, last cycle of 3 s), eq. (11a, c) per leg is
    sqrt(offset^2 + detrended^2): the decomposition gives the paper's eps_xH and eps_xF
    back, and trk_xH, trk_xF are the detrended parts."""
    from hexapod_bringup.core.simulate import simulate, window_ticks
    from hexapod_metrics.core.indices import sums_from_obs

    p = load_params()
    sim = simulate(p, controller)
    k_a, k_b = window_ticks(p, p.run.duration)
    sl = slice(k_a, k_b + 1)
    s = sums_from_obs(sim.run.obs[sl], sim.run.reference.hip[sl], sim.run.reference.foot[sl],
                      p.sim.control_period)
    offset, detrended = s.x_error_parts()
    per_leg = np.sqrt(s.sq_err[[0, 2]] / s.samples)
    np.testing.assert_allclose(np.sqrt(offset ** 2 + detrended ** 2), per_leg, rtol=1e-10)
    idx = sim.indices
    assert idx is not None
    assert idx.eps_xH == pytest.approx(np.sqrt(offset[0] ** 2 + detrended[0] ** 2).sum(),
                                       rel=1e-10)
    assert idx.eps_xF == pytest.approx(np.sqrt(offset[1] ** 2 + detrended[1] ** 2).sum(),
                                       rel=1e-10)
    assert idx.trk_xH == pytest.approx(detrended[0].sum(), rel=1e-10)
    assert idx.trk_xF == pytest.approx(detrended[1].sum(), rel=1e-10)
    assert np.abs(offset).max() > 1e-3  # the offset is a real part of eps_x, not a rounding


def test_the_drift_gap_between_controllers_exceeds_its_dt_band(long_runs):
    for name in ("drift_xH", "drift_xF"):
        bands = {c: [getattr(o.cycles[10], name) for o in long_runs[c][1]] for c in CONTROLLERS}
        width = max(max(b) - min(b) for b in bands.values())
        gap = min(bands["pd_p"]) - max(bands["pd_pf"])
        assert gap > width, (name, bands)  # the bands are apart by more than a band


def _at_cycle(outcome, cycle):
    return outcome.at_cycle(cycle)


def test_a_cycle_of_a_long_run_is_the_window_of_a_run_that_ends_there(long_runs):
    """Outcome.at_cycle(2) of the 21 s run is what a 3 s run scores (its last cycle), to the
    bit; a cycle the run never reached has no indices."""
    p = load_params()
    short = evaluate_batch([Case(p, c) for c in CONTROLLERS], 3.0)
    for c, s in zip(CONTROLLERS, short):
        at = long_runs[c][0].at_cycle(2)
        assert at.indices == s.indices and at.window == s.window == (2.0, 3.0)
        assert at.status == "ok"
        assert long_runs[c][0].at_cycle(21).indices is None


def test_eq11_per_leg_is_offset_and_tracking_in_quadrature():
    rng = np.random.default_rng(3)
    n = 101
    hip, foot = rng.normal(size=(n, 6, 2)), rng.normal(size=(n, 6, 2))
    hip_ref = hip + 0.01 * rng.normal(size=(n, 6, 2)) + 0.02  # an offset
    foot_ref = foot + 0.01 * rng.normal(size=(n, 6, 2)) + np.linspace(0, 0.05, n)[:, None, None]
    z = np.zeros((n, 6, 2))
    s = window_sums(z, z, z, hip, hip_ref, foot, foot_ref, 1e-3)
    offset, trk = s.x_error_parts()
    per_leg = np.sqrt(s.sq_err[[0, 2]] / s.samples)
    np.testing.assert_allclose(np.sqrt(offset ** 2 + trk ** 2), per_leg, rtol=1e-12)
    e = (hip_ref - hip)[1:, :, 0]
    np.testing.assert_allclose(trk[0], e.std(axis=0), rtol=1e-9)
    idx = s.indices()
    assert idx.trk_xH == pytest.approx(e.std(axis=0).sum(), rel=1e-9)
    ef = (foot_ref - foot)[:, :, 0]
    assert idx.drift_xF == pytest.approx((ef[-1] - ef[0]).mean() / ((n - 1) * 1e-3), rel=1e-9)
    # two consecutive windows add up to the window over both
    a = window_sums(z[:51], z[:51], z[:51], hip[:51], hip_ref[:51], foot[:51], foot_ref[:51],
                    1e-3)
    b = window_sums(z[50:], z[50:], z[50:], hip[50:], hip_ref[50:], foot[50:], foot_ref[50:],
                    1e-3)
    both = (a + b).indices()
    assert both.drift_xF == pytest.approx(idx.drift_xF, rel=1e-9)
    assert both.trk_xH == pytest.approx(idx.trk_xH, rel=1e-9)
