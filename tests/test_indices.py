"""Indices on synthetic signals whose values are known in closed form."""
import numpy as np
import pytest

from hexapod_metrics.core.indices import compute_indices, evaluation_window, window_sums
from hexapod_common.core.errors import ParameterError
from hexapod_common.core.params import load_params


def _window(n=1000, dt=1e-3):
    t = np.arange(n + 1) * dt
    hip = np.zeros((n + 1, 6, 2))
    hip[..., 0] = t[:, None] * 2.0         # walks 2 m in 1 s
    hip[..., 1] = 1.8
    return t, hip


def test_constant_signals():
    n, dt = 1000, 1e-3
    t, hip = _window(n, dt)
    torque = np.full((n + 1, 6, 2), 2.0)
    vel = np.full((n + 1, 6, 2), -3.0)
    force = np.tile([3.0, 4.0], (n + 1, 6, 1))
    hip_ref = hip.copy()
    hip_ref[..., 0] += 0.1
    foot = np.zeros((n + 1, 6, 2))
    foot_ref = foot.copy()
    foot_ref[..., 1] -= 0.05
    idx = compute_indices(torque, vel, force, hip, hip_ref, foot, foot_ref, dt)
    assert idx.L == pytest.approx(2.0)
    assert idx.E_av == pytest.approx(12 * 6.0 * 1.0 / 2.0)     # 12 joints x |2*-3| x 1 s / 2 m
    assert idx.T_L == pytest.approx(np.sqrt(12 * 4.0 * 1.0) / 2.0)
    assert idx.F_L == pytest.approx(np.sqrt(6 * 25.0 * 1.0) / 2.0)
    assert idx.eps_xH == pytest.approx(0.6) and idx.eps_yH == 0.0
    assert idx.eps_xF == 0.0 and idx.eps_yF == pytest.approx(0.3)


def test_sinusoidal_errors_and_power():
    n, dt = 1000, 1e-3
    t, hip = _window(n, dt)
    w = 2 * np.pi                       # one full period over the window
    torque = np.zeros((n + 1, 6, 2))
    vel = np.zeros((n + 1, 6, 2))
    torque[:, 0, 0] = 10 * np.sin(w * t)
    vel[:, 0, 0] = 2 * np.sin(w * t)    # power 20 sin^2 >= 0: energy = 20 * 0.5 * 1 s
    hip_ref = hip.copy()
    hip_ref[:, 2, 1] += 0.3 * np.sin(w * t)
    zeros = np.zeros((n + 1, 6, 2))
    idx = compute_indices(torque, vel, zeros, hip, hip_ref, zeros, zeros, dt)
    assert idx.E_av == pytest.approx(20 * 0.5 / 2.0, rel=1e-9)
    assert idx.T_L == pytest.approx(np.sqrt(100 * 0.5) / 2.0, rel=1e-9)
    assert idx.eps_yH == pytest.approx(0.3 / np.sqrt(2), rel=1e-9)
    assert idx.F_L == 0.0


def test_first_sample_only_sets_the_start():
    n, dt = 10, 0.1
    t, hip = _window(n, dt)
    torque = np.zeros((n + 1, 6, 2))
    torque[0] = 1e6                      # ignored: it belongs to the previous window
    z = np.zeros((n + 1, 6, 2))
    assert compute_indices(torque, z + 1, z, hip, hip, z, z, dt).E_av == 0.0


def test_evaluation_window():
    p = load_params()
    assert evaluation_window(p, 3.0) == (2.0, 3.0)
    assert evaluation_window(p, 3.5) == (2.0, 3.0)
    with pytest.raises(ParameterError, match="run.duration"):
        evaluation_window(p, 0.5)


def test_window_sums_add_up_over_consecutive_windows():
    from hexapod_metrics.core.indices import window_sums

    rng = np.random.default_rng(2)
    n, dt = 200, 1e-3
    t, hip = _window(n, dt)
    arrays = [rng.normal(size=(n + 1, 6, 2)) for _ in range(3)]
    hip_ref = hip + rng.normal(scale=0.01, size=hip.shape)
    foot, foot_ref = rng.normal(size=(2, n + 1, 6, 2))
    whole = compute_indices(*arrays, hip, hip_ref, foot, foot_ref, dt)
    parts = [window_sums(*(a[sl] for a in arrays), hip[sl], hip_ref[sl], foot[sl],
                         foot_ref[sl], dt) for sl in (slice(0, 81), slice(80, 201))]
    joined = (parts[0] + parts[1]).indices()
    for name in ("E_av", "T_L", "F_L", "eps_xH", "eps_yH", "eps_xF", "eps_yF", "L"):
        assert getattr(joined, name) == pytest.approx(getattr(whole, name), rel=1e-12)


def test_hip_lag_and_its_growth_tell_drift_from_tracking():
    """A hip that trails its reference by a growing amount: eps_xH grows with the lag, the
    lag itself is the mean trailing distance, and its growth per cycle is the drift."""
    from hexapod_metrics.core.indices import lag_growth, window_sums

    n, dt = 1000, 1e-3
    t, hip_ref = _window(n, dt)
    zeros = np.zeros((n + 1, 6, 2))
    cycles = []
    for c in range(3):
        hip = hip_ref.copy()
        hip[..., 0] -= 0.01 * (c + 1)          # cycle c trails by (c+1) cm, on every leg
        hip[:, 3, 0] -= 0.006                  # leg 4 trails 6 mm more
        cycles.append(window_sums(zeros, zeros, zeros, hip, hip_ref, zeros, zeros, dt))
    idx = [s.indices() for s in cycles]
    assert idx[0].lag_xH == pytest.approx(0.011)          # (6 x 1 cm + 6 mm) / 6
    assert idx[0].eps_xH == pytest.approx(5 * 0.01 + 0.016)
    assert lag_growth(idx[0], idx[1]) == pytest.approx(0.01)
    assert lag_growth(idx[1], idx[2]) == pytest.approx(0.01)
    assert np.isnan(lag_growth(None, idx[0]))
    both = (cycles[0] + cycles[1]).indices()               # sums add over windows
    assert both.lag_xH == pytest.approx(0.016)


def test_compiled_sums_equal_the_plain_numpy_sums():
    """The one compiled accumulator (index_sums, shared with the batched engine) against the
    equations written out in numpy, on random samples."""
    rng = np.random.default_rng(7)
    tq, w, f, hp, hr, fp, fr = (rng.normal(size=(501, 6, 2)) for _ in range(7))
    dt = 1e-3
    s = window_sums(tq, w, f, hp, hr, fp, fr, dt)
    eh, ef = hr[1:] - hp[1:], fr[1:] - fp[1:]
    assert s.energy == pytest.approx(np.sum(np.abs(tq[1:] * w[1:])) * dt, rel=1e-12)
    assert s.torque2 == pytest.approx(np.sum(tq[1:] ** 2) * dt, rel=1e-12)
    assert s.force2 == pytest.approx(np.sum(f[1:] ** 2) * dt, rel=1e-12)
    sq = np.stack([np.sum(eh[..., 0] ** 2, 0), np.sum(eh[..., 1] ** 2, 0),
                   np.sum(ef[..., 0] ** 2, 0), np.sum(ef[..., 1] ** 2, 0)])
    assert np.allclose(s.sq_err, sq, rtol=1e-12, atol=0)
    assert s.samples == 500
    assert s.distance == np.mean(hp[-1, :, 0] - hp[0, :, 0])
    assert s.lag == pytest.approx(np.sum(eh[..., 0]), rel=1e-9)
