"""Our per-leg dynamics against the same planar model built in MuJoCo (quality.md S3).

MuJoCo computes H and c + g by its own recursive algorithms from bodies and joints
(hexapod_sim/mujoco_model.py), so agreement to round-off checks every term of dynamics.py,
the angle conventions and, through ``xfrc_applied``, the Jacobian transposes that carry the
hip and foot forces. Besides the base case (L1 = L2, M1 = M2, which would hide swapped
terms) a lopsided leg is used. The six-leg model checks engine.advance (semi-implicit Euler,
body springs) step by step with the ground switched off.
"""
from __future__ import annotations

import inspect

import numpy as np
import pytest

mujoco = pytest.importorskip(
    "mujoco", reason="mujoco (PyPI) is not installed: the S3 reference model cannot be built")

from hexapod_sim import mujoco_model as mm  # noqa: E402
from hexapod_sim.core import dynamics, engine  # noqa: E402
from hexapod_common.core import layout as L  # noqa: E402
from hexapod_common.core.params import SPECS, N_LEGS, HexapodParams, load_params  # noqa: E402

N_STATES = 50
TOL = 1e-9

# leg_accel's first 16 arguments are the explicit model of model.md; any further ones (the
# engine's optional implicit ground damping: B_gx, B_gy, h) are zero here, the explicit solve.
_N_ACCEL_ARGS = len(inspect.signature(dynamics.leg_accel.py_func).parameters)


def _base() -> HexapodParams:
    return load_params()


def _lopsided() -> HexapodParams:
    return load_params(**{"robot.leg_length_1": 0.9, "robot.leg_length_2": 1.25,
                          "robot.mass_1": 2.5, "robot.mass_2": 0.7, "robot.body_mass": 60.0})


PARAM_SETS = {"base": _base, "lopsided": _lopsided}


def _rel(a: np.ndarray, b: np.ndarray) -> float:
    """Norm-wise relative difference of a to the reference b."""
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def _leg(p: HexapodParams) -> tuple[float, float, float, float, float]:
    r = p.robot
    return r.leg_length_1, r.leg_length_2, r.body_mass / N_LEGS, r.mass_1, r.mass_2


def _our_accel(p: HexapodParams, q: np.ndarray, dq: np.ndarray, tm: np.ndarray,
               fh: np.ndarray, ff: np.ndarray) -> np.ndarray:
    """dynamics.leg_accel with joint torques tm, hip force fh and foot force ff."""
    args = (q[2], q[3], dq[2], dq[3], *_leg(p), L.GRAVITY, tm[0], tm[1], fh[0], fh[1],
            ff[0], ff[1])
    return np.array(dynamics.leg_accel(*args, *(0.0,) * (_N_ACCEL_ARGS - len(args))))


def _states(seed: int) -> list[tuple[np.ndarray, np.ndarray]]:
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(N_STATES):
        q = np.concatenate([rng.uniform(-5.0, 5.0, 2), rng.uniform(-np.pi, np.pi, 2)])
        dq = np.concatenate([rng.uniform(-3.0, 3.0, 2), rng.uniform(-20.0, 20.0, 2)])
        out.append((q, dq))
    return out


@pytest.fixture(params=sorted(PARAM_SETS))
def leg(request: pytest.FixtureRequest) -> tuple[HexapodParams, object, object]:
    p = PARAM_SETS[request.param]()
    model = mm.build_leg_model(p)
    return p, model, mujoco.MjData(model)


def test_model_matches_conventions(leg: tuple) -> None:
    """qpos = our q: the knee and foot land where model.md's kinematics put them."""
    p, model, data = leg
    l1, l2 = p.robot.leg_length_1, p.robot.leg_length_2
    q = np.array([0.3, 1.7, 0.4, -0.9])
    mm.set_leg_state(model, data, q, np.zeros(4))
    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)
    knee = q[:2] + l1 * np.array([np.sin(q[2]), -np.cos(q[2])])
    foot = knee + l2 * np.array([np.sin(q[2] + q[3]), -np.cos(q[2] + q[3])])
    thigh = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "thigh")
    shank = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "shank")
    np.testing.assert_allclose(data.xipos[thigh, :2], knee, atol=1e-14)
    np.testing.assert_allclose(data.xipos[shank, :2], foot, atol=1e-14)
    assert model.opt.timestep == p.sim.dt
    np.testing.assert_array_equal(model.opt.gravity, [0.0, -L.GRAVITY, 0.0])


def test_mass_matrix_and_bias_equal_mujoco(leg: tuple) -> None:
    p, model, data = leg
    l1, l2, mh, mk, mf = _leg(p)
    worst_h, worst_b = 0.0, 0.0
    for q, dq in _states(seed=20030630):
        H_mj, bias_mj = mm.mass_matrix_and_bias(model, data, q, dq)
        H = dynamics.mass_matrix(q, l1, l2, mh, mk, mf)
        bias = dynamics.bias_forces(q, dq, l1, l2, mh, mk, mf, L.GRAVITY)
        worst_h = max(worst_h, _rel(H, H_mj))
        worst_b = max(worst_b, _rel(bias, bias_mj))
    assert worst_h < TOL, f"H differs from MuJoCo's by {worst_h:.3g} (relative)"
    assert worst_b < TOL, f"c + g differs from MuJoCo's by {worst_b:.3g} (relative)"


def test_unforced_acceleration_equals_mujoco(leg: tuple) -> None:
    p, model, data = leg
    worst = 0.0
    for q, dq in _states(seed=7):
        acc_mj = mm.leg_accel(model, data, q, dq)
        zero = np.zeros(2)
        acc = _our_accel(p, q, dq, zero, zero, zero)
        worst = max(worst, _rel(acc, acc_mj))
    assert worst < TOL, f"ddq differs from MuJoCo's qacc by {worst:.3g} (relative)"


def test_forced_acceleration_equals_mujoco(leg: tuple) -> None:
    """Joint torques through MuJoCo motors, hip and foot forces through xfrc_applied."""
    p, model, data = leg
    rng = np.random.default_rng(11)
    worst = 0.0
    for q, dq in _states(seed=8):
        tm = rng.uniform(-400.0, 400.0, 2)
        fh = rng.uniform(-2000.0, 2000.0, 2)
        ff = rng.uniform(-2000.0, 2000.0, 2)
        acc_mj = mm.leg_accel(model, data, q, dq, tm, fh, ff)
        acc = _our_accel(p, q, dq, tm, fh, ff)
        worst = max(worst, _rel(acc, acc_mj))
    assert worst < TOL, f"forced ddq differs from MuJoCo's qacc by {worst:.3g} (relative)"


@pytest.mark.parametrize("name", sorted(PARAM_SETS))
def test_engine_steps_equal_mujoco_without_ground(name: str) -> None:
    """engine.advance (six legs, body springs, ground gains zeroed) against mj_step of the
    six-leg model with the body links as fixed tendons, same dt, same semi-implicit Euler."""
    p = PARAM_SETS[name]()
    if "sim.integrator" in SPECS:  # model.md's scheme, which is MuJoCo's Euler
        p = p.with_values(**{"sim.integrator": "semi_implicit_euler"})
    model = mm.build_hexapod_model(p)
    data = mujoco.MjData(model)
    rng = np.random.default_rng(3)
    s = engine.initial_state(p)
    s[L.Q0:L.Q0 + 24] += rng.normal(0.0, 0.05, 24)
    s[L.V0:L.V0 + 24] += rng.normal(0.0, 0.5, 24)
    P = L.model_vector(p)
    P[[L.P_KGX, L.P_KGY, L.P_BGX, L.P_BGY]] = 0.0
    torque = rng.uniform(-100.0, 100.0, (N_LEGS, 2))
    mm.set_leg_state(model, data, s[L.Q0:L.Q0 + 24], s[L.V0:L.V0 + 24])
    data.ctrl[:] = torque.ravel()
    n_steps = 1000
    assert engine.advance(s, torque, P, n_steps)
    mujoco.mj_step(model, data, nstep=n_steps)
    err_q = _rel(s[L.Q0:L.Q0 + 24], data.qpos)
    err_v = _rel(s[L.V0:L.V0 + 24], data.qvel)
    assert err_q < TOL and err_v < TOL, (
        f"after {n_steps} steps q differs by {err_q:.3g}, dq by {err_v:.3g} (relative)")
    # The run went somewhere: a wrong spring sign or a missing term would not stay this close.
    assert np.linalg.norm(data.qvel) > 1.0
