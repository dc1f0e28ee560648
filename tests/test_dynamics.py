"""Dynamics: energy conservation of the unforced, undamped model; contact and body laws."""
import numpy as np
import pytest

from hexapod_sim.core.body import LINKS, body_forces
from hexapod_sim.core.contact import limit_force, spring_damper, update_contact
from hexapod_sim.core.dynamics import bias_forces, leg_accel, mass_matrix
from hexapod_sim.core.engine import advance, initial_state, legs
from hexapod_common.core.layout import (MODEL_SIZE, P_BBX, P_BBY, P_G, P_HIPX, P_KBX, P_KBY, P_L1,
                                        P_L2, P_MF, P_MH, P_MK, Q0, STATE_SIZE, V0, model_vector)
from hexapod_common.core.params import load_params


def energy(s, P):
    """Kinetic + gravitational + body-spring energy of the whole robot (J)."""
    q, dq = legs(s)
    l1, l2, g = P[P_L1], P[P_L2], P[P_G]
    e = 0.0
    for i in range(6):
        xh, yh, t1, t2 = q[i]
        vxh, vyh, w1, w2 = dq[i]
        vk = np.array([vxh + l1 * np.cos(t1) * w1, vyh + l1 * np.sin(t1) * w1])
        vf = vk + l2 * (w1 + w2) * np.array([np.cos(t1 + t2), np.sin(t1 + t2)])
        yk = yh - l1 * np.cos(t1)
        yf = yk - l2 * np.cos(t1 + t2)
        e += 0.5 * (P[P_MH] * (vxh**2 + vyh**2) + P[P_MK] * vk @ vk + P[P_MF] * vf @ vf)
        e += g * (P[P_MH] * yh + P[P_MK] * yk + P[P_MF] * yf)
    x0 = P[P_HIPX:P_HIPX + 6]
    for a, b in LINKS:
        dx = q[b, 0] - q[a, 0] - (x0[b] - x0[a])
        e += 0.5 * (P[P_KBX] * dx**2 + P[P_KBY] * (q[b, 1] - q[a, 1]) ** 2)
    return e


def test_energy_conserved_without_ground_damping_and_torque():
    p = load_params(**{"ground.k_x": 0.0, "ground.k_y": 0.0, "ground.b_x": 0.0,
                       "ground.b_y": 0.0, "body.b_x": 0.0, "body.b_y": 0.0})
    P = model_vector(p)
    s = initial_state(p)
    # perturb so the springs and the joints really move
    rng = np.random.default_rng(3)
    s[24:48] += rng.normal(scale=0.5, size=24)
    torque = np.zeros((6, 2))
    e0 = energy(s, P)
    scale = 0.0
    drift = 0.0
    for _ in range(100):  # 100 x 100 steps of 1e-4 s = 1 s
        assert advance(s, torque, P, 100)
        e = energy(s, P)
        _, dq = legs(s)
        scale = max(scale, abs(e0), 0.5 * P[P_MH] * 6 * float(np.max(dq[:, :2] ** 2)))
        drift = max(drift, abs(e - e0))
    assert drift / scale < 2e-3, f"energy drift {drift:.3g} J of {scale:.3g} J"


def test_energy_drift_shrinks_with_dt():
    """Semi-implicit Euler: the drift is first order in dt (a check that can fail)."""
    drifts = []
    for dt in (2e-4, 1e-4):
        p = load_params(**{"ground.k_x": 0.0, "ground.k_y": 0.0, "ground.b_x": 0.0,
                           "ground.b_y": 0.0, "body.b_x": 0.0, "body.b_y": 0.0, "sim.dt": dt,
                           "sim.control_period": 1e-3})  # a multiple of both steps
        P = model_vector(p)
        s = initial_state(p)
        s[24:48] += np.random.default_rng(4).normal(scale=0.5, size=24)
        e0 = energy(s, P)
        n = int(round(0.5 / dt))
        assert advance(s, np.zeros((6, 2)), P, n)
        drifts.append(abs(energy(s, P) - e0))
    assert drifts[1] < 0.75 * drifts[0]


def test_free_fall_of_a_locked_leg():
    """With H ddq = -g and no forces, the hip falls with exactly g when the leg is straight."""
    a = leg_accel(0.0, -0.5, 0.0, 0.0, 1.0, 1.0, 14.0, 1.0, 1.0, 9.81, 0.0, 0.0, 0.0, 0.0,
                  0.0, 0.0, 0.0, 0.0, 0.0)
    np.testing.assert_allclose(a, [0.0, -9.81, 0.0, 0.0], atol=1e-12)


def test_mass_matrix_symmetric_positive_definite():
    rng = np.random.default_rng(5)
    for _ in range(20):
        q = rng.normal(size=4)
        h = mass_matrix(q, 1.0, 0.9, 14.0, 1.0, 1.5)
        np.testing.assert_allclose(h, h.T)
        assert np.all(np.linalg.eigvalsh(h) > 0)


def test_accel_solves_equation_of_motion():
    rng = np.random.default_rng(6)
    for _ in range(20):
        q, dq = rng.normal(size=4), rng.normal(size=4)
        tm, fh, ff = rng.normal(size=2) * 50, rng.normal(size=2) * 100, rng.normal(size=2) * 100
        bx, by, step = rng.uniform(0, 1e4, size=2).tolist() + [1e-4]
        a = np.array(leg_accel(q[2], q[3], dq[2], dq[3], 1.0, 1.0, 14.0, 1.0, 1.0, 9.81,
                               tm[0], tm[1], fh[0], fh[1], ff[0], ff[1], bx, by, step))
        h = mass_matrix(q, 1.0, 1.0, 14.0, 1.0, 1.0)
        b = bias_forces(q, dq, 1.0, 1.0, 14.0, 1.0, 1.0, 9.81)
        c1, s1 = np.cos(q[2]), np.sin(q[2])
        c12, s12 = np.cos(q[2] + q[3]), np.sin(q[2] + q[3])
        jf = np.array([[1, 0, c1 + c12, c12], [0, 1, s1 + s12, s12]])
        # the ground damping is taken at the end-of-step velocity: F = ff - step B J_F a
        f_end = ff - step * np.array([bx, by]) * (jf @ a)
        rhs = np.array([0, 0, tm[0], tm[1]]) + np.r_[fh, 0, 0] + jf.T @ f_end - b
        np.testing.assert_allclose(h @ a, rhs, rtol=1e-10, atol=1e-9)


def _ground_force(x, y, vx, vy, in_contact, x_touch, kx, ky, bx, by, mu):
    """The engines' sequence: contact state, the law, then the limits."""
    c, xt = update_contact(x, y, in_contact, x_touch)
    if c == 0.0:
        return 0.0, 0.0, 0.0, 0.0
    fx, fy = limit_force(*spring_damper(x, y, vx, vy, xt, kx, ky, bx, by), mu)
    return fx, fy, c, xt


def test_ground_force_law():
    k, d = 1e6, 1e4
    ground_force = _ground_force
    # above ground: nothing, contact forgotten
    assert ground_force(0.3, 0.01, 0.0, 0.0, 1.0, 0.2, 1e5, k, 1e3, d, 0.0) == (0, 0, 0, 0)
    # first instant of contact stores the touchdown point
    fx, fy, c, xt = ground_force(0.3, -0.001, 0.0, -0.1, 0.0, 0.0, 1e5, k, 1e3, d, 0.0)
    assert (c, xt) == (1.0, 0.3) and fx == 0.0 and fy == pytest.approx(k * 0.001 + d * 0.1)
    # sliding away from it pulls back along x
    fx, fy, c, xt = ground_force(0.31, -0.001, 0.0, 0.0, 1.0, 0.3, 1e5, k, 1e3, d, 0.0)
    assert xt == 0.3 and fx == pytest.approx(-1e5 * 0.01)
    # the ground never pulls
    assert ground_force(0.3, -0.001, 0.0, 1.0, 1.0, 0.3, 1e5, k, 1e3, d, 0.0)[1] == 0.0
    # optional Coulomb limit
    fx, fy, *_ = ground_force(0.5, -0.001, 0.0, 0.0, 1.0, 0.3, 1e5, k, 1e3, d, 0.5)
    assert fx == pytest.approx(-0.5 * fy)


def _body_state(q: np.ndarray, dq: np.ndarray) -> np.ndarray:
    """A state vector holding leg coordinates q and rates dq (6, 4)."""
    s = np.zeros(STATE_SIZE)
    s[Q0:Q0 + 24], s[V0:V0 + 24] = q.ravel(), dq.ravel()
    return s


def _body_model(hip_x0: np.ndarray) -> np.ndarray:
    P = np.zeros(MODEL_SIZE)
    P[P_KBX], P[P_KBY], P[P_BBX], P[P_BBY] = 1e5, 1e4, 1e3, 1e2
    P[P_HIPX:P_HIPX + 6] = hip_x0
    return P


def test_body_forces_are_internal():
    rng = np.random.default_rng(7)
    q, dq = rng.normal(size=(6, 4)), rng.normal(size=(6, 4))
    out = np.empty((6, 2))
    body_forces(_body_state(q, dq), _body_model(-(np.arange(6) // 2) * 1.0), out)
    np.testing.assert_allclose(out.sum(axis=0), 0.0, atol=1e-7)
    # at rest in the nominal layout there is no force
    q2 = np.zeros((6, 4))
    q2[:, 0] = -(np.arange(6) // 2) * 1.0
    body_forces(_body_state(q2, np.zeros((6, 4))), _body_model(q2[:, 0].copy()), out)
    np.testing.assert_array_equal(out, 0.0)
    # hip 2 (index 1) moved 1 cm forward stretches its links to hips 1 and 4 (0 and 3): each
    # pulls with K_bx times 1 cm
    q3 = q2.copy()
    q3[1, 0] += 0.01
    body_forces(_body_state(q3, np.zeros((6, 4))), _body_model(q2[:, 0].copy()), out)
    np.testing.assert_allclose(out[:, 0], [1e3, -2e3, 0.0, 1e3, 0.0, 0.0], rtol=1e-9)
    np.testing.assert_array_equal(out[:, 1], 0.0)
