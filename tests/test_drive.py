"""The simulated drive: a torque-only command gives the held-torque engine's numbers bit for
bit; the drive law's terms each act as model.md's formula says."""
import math

import numpy as np
import pytest

from hexapod_common.core.layout import OBS_SHAPE, model_vector
from hexapod_common.core.params import load_params
from hexapod_sim.core.actuator import saturate
from hexapod_sim.core.drive import (C_DQREF, C_KD, C_KF, C_KP, C_QREF, COMMAND_SHAPE,
                                    drive_advance, drive_torques, torque_only)
from hexapod_sim.core.engine import (advance_prepared, initial_state, observe_prepared,
                                     scratch)


@pytest.mark.parametrize("t_max", [150.0, math.inf])
@pytest.mark.parametrize("control_period", [5e-5, 1e-3])
def test_torque_only_command_is_bit_identical_to_the_held_torque(t_max, control_period):
    """Same state, same demanded torques (some beyond T_max): drive_advance with
    kp = kd = k_force = 0 and advance_prepared holding clip(T) give equal states and
    equal torques acting, over many ticks and substeps."""
    p = load_params(**{"actuator.t_max": t_max, "sim.control_period": control_period})
    P = model_vector(p)
    rng = np.random.default_rng(7)
    s_a, s_b = initial_state(p), initial_state(p)
    tq_a, tq_b = np.zeros((6, 2)), np.zeros((6, 2))
    sc_a, sc_b = scratch(), scratch()
    obs_a, obs_b = np.empty(OBS_SHAPE), np.empty(OBS_SHAPE)
    demand0 = np.empty((6, 2))
    for _ in range(40):
        T = rng.normal(0.0, 200.0, (6, 2))
        observe_prepared(s_a, tq_a, P, obs_a, *sc_a)
        observe_prepared(s_b, tq_b, P, obs_b, *sc_b)
        np.testing.assert_array_equal(obs_a, obs_b)
        assert drive_advance(s_a, torque_only(T), P, p.substeps, *sc_a, demand0, tq_a)
        saturate(T, t_max, tq_b)
        assert advance_prepared(s_b, tq_b, P, p.substeps, *sc_b)
        np.testing.assert_array_equal(demand0, T)
        np.testing.assert_array_equal(tq_a, tq_b)
        np.testing.assert_array_equal(s_a, s_b)
    assert np.any(np.abs(tq_b) == t_max) or math.isinf(t_max)


def test_drive_law_terms():
    """T = kp (q_ref + dq_ref elapsed - q) + kd (dq_ref - dq) + tau_ff - k_force tau_F, then
    the saturation; the force term uses the foot force given (zero force: no term)."""
    p = load_params()
    s = initial_state(p)
    cmd = np.zeros(COMMAND_SHAPE)
    cmd[C_QREF] = 0.5
    cmd[C_DQREF] = 2.0
    cmd[C_KP] = 100.0
    cmd[C_KD] = 10.0
    q = s[2:24:4], s[3:24:4]
    dq = s[24 + 2:48:4], s[24 + 3:48:4]
    demand, torque = np.empty((6, 2)), np.empty((6, 2))
    drive_torques(cmd, s, np.zeros((6, 2)), 0.01, 1.0, 1.0, 1e9, demand, torque)
    for j in range(2):
        want = 100.0 * (0.5 + 2.0 * 0.01 - q[j]) + 10.0 * (2.0 - dq[j])
        np.testing.assert_allclose(demand[:, j], want, rtol=1e-14)
    cmd[C_KF] = 1.0
    ff = np.tile([30.0, 500.0], (6, 1))
    drive_torques(cmd, s, ff, 0.01, 1.0, 1.0, 5.0, demand, torque)
    assert not np.allclose(demand[:, 0], 100.0 * (0.5 + 0.02 - q[0]) + 10.0 * (2.0 - dq[0]))
    np.testing.assert_array_equal(torque, np.clip(demand, -5.0, 5.0))
