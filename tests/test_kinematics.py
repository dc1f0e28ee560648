"""Kinematics: IK/FK round trip over the whole gait, Jacobians against finite differences."""
import numpy as np
import pytest

from hexapod_common.core.errors import UnreachableTargetError
from hexapod_common.core.gait import reference
from hexapod_common.core.kinematics import (foot_force_torque, foot_offset, ik_scalar,
                                            ik_with_rates, inverse_kinematics, joint_rates,
                                            psi, psi_jacobian)
from hexapod_common.core.params import load_params


def test_ik_fk_round_trip_over_whole_gait():
    p = load_params()
    t = np.linspace(0.0, 2 * p.cycle_time, 4001)
    ref = reference(p, t)
    px, py = psi(ref.theta[..., 0], ref.theta[..., 1], 1.0, 1.0)
    rel = ref.hip - ref.foot
    np.testing.assert_allclose(px, rel[..., 0], atol=1e-12)
    np.testing.assert_allclose(py, rel[..., 1], atol=1e-12)
    assert np.all(ref.theta[..., 1] < 0.0), "forward knee means theta2 < 0"


def test_ik_picks_forward_knee():
    th1, th2 = inverse_kinematics(0.0, 1.5, 1.0, 1.0)
    kx = np.sin(th1)
    assert th2 < 0 and kx > 0, "knee must sit forward (+x) of the hip-foot line"


@pytest.mark.parametrize("target", [(0.0, 2.0001), (2.5, 0.0), (3.0, 0.1), (np.nan, 1.0)])
def test_ik_raises_outside_annulus(target):
    with pytest.raises(UnreachableTargetError, match="outside the leg's reach"):
        inverse_kinematics(*target, 1.0, 1.0)


def test_ik_unequal_links_inner_boundary():
    with pytest.raises(UnreachableTargetError):
        inverse_kinematics(0.0, 0.3, 1.0, 0.5)
    th1, th2 = inverse_kinematics(0.0, 0.6, 1.0, 0.5)
    np.testing.assert_allclose(psi(th1, th2, 1.0, 0.5), (0.0, 0.6), atol=1e-12)


def test_jacobian_against_finite_differences():
    rng = np.random.default_rng(0)
    h = 1e-6
    for _ in range(50):
        th1, th2 = rng.uniform(-1.5, 1.5), rng.uniform(-2.5, -0.1)
        l1, l2 = rng.uniform(0.5, 1.5, size=2)
        j = np.array(psi_jacobian(th1, th2, l1, l2)).reshape(2, 2)
        fd = np.empty((2, 2))
        for col, (d1, d2) in enumerate([(h, 0.0), (0.0, h)]):
            plus = np.array(psi(th1 + d1, th2 + d2, l1, l2))
            minus = np.array(psi(th1 - d1, th2 - d2, l1, l2))
            fd[:, col] = (plus - minus) / (2 * h)
        np.testing.assert_allclose(j, fd, atol=1e-8)


def test_joint_rates_invert_jacobian():
    th1, th2, vx, vy = 0.3, -0.8, 0.7, -0.2
    w1, w2 = joint_rates(th1, th2, vx, vy, 1.0, 1.0)
    j = np.array(psi_jacobian(th1, th2, 1.0, 1.0)).reshape(2, 2)
    np.testing.assert_allclose(j @ [w1, w2], [vx, vy], atol=1e-12)


def test_reference_joint_rates_match_numerical_derivative():
    p = load_params()
    t = np.linspace(0.05, 0.95, 901)
    ref = reference(p, t)
    h = 1e-6
    fd = (reference(p, t + h).theta - reference(p, t - h).theta) / (2 * h)
    np.testing.assert_allclose(ref.theta_vel, fd, atol=1e-5)


def test_foot_force_torque_is_virtual_work():
    # tau = J_F^T F: the power tau . dtheta equals F . v_foot for any motion of the joints.
    rng = np.random.default_rng(1)
    th1, th2, w1, w2, fx, fy = rng.normal(size=6)
    tau = np.array(foot_force_torque(th1, th2, fx, fy, 1.0, 0.8))
    h = 1e-7
    a = np.array(foot_offset(th1 + h * w1, th2 + h * w2, 1.0, 0.8))
    b = np.array(foot_offset(th1 - h * w1, th2 - h * w2, 1.0, 0.8))
    v = (a - b) / (2 * h)
    assert tau @ [w1, w2] == pytest.approx(v @ [fx, fy], rel=1e-7)


def test_ik_with_rates_equals_ik_then_inverse_jacobian():
    """The reference's one-call IK and rates (no J trigonometry) against ik_scalar and
    joint_rates over the whole workspace (forward knee, away from the straight leg)."""
    rng = np.random.default_rng(3)
    l1, l2 = 0.5, 0.4
    for _ in range(500):
        th1, th2 = rng.uniform(-1.2, 1.2), rng.uniform(-2.8, -0.05)
        px = -(l1 * np.sin(th1) + l2 * np.sin(th1 + th2))
        py = l1 * np.cos(th1) + l2 * np.cos(th1 + th2)
        vx, vy = rng.normal(size=2)
        r2 = px * px + py * py
        t1, t2, w1, w2 = ik_with_rates(px, py, r2, vx, vy, l1, l2)
        e1, e2 = ik_scalar(px, py, r2, l1, l2)
        f1, f2 = joint_rates(e1, e2, vx, vy, l1, l2)
        assert (t1, t2) == (e1, e2)
        assert t1 == pytest.approx(th1, abs=1e-12) and t2 == pytest.approx(th2, abs=1e-12)
        assert w1 == pytest.approx(f1, rel=1e-9, abs=1e-9)
        assert w2 == pytest.approx(f2, rel=1e-9, abs=1e-9)
