"""The simulated joint drive (model.md "Drive interface and force loop placement").

The drive holds the last command of every joint, a (6, 6, 2) array of
(q_ref, dq_ref, kp, kd, tau_ff, k_force) per leg and joint (rad, rad/s, N m/rad,
N m s/rad, N m, 1), and evaluates at every physics step

    T = kp (q_ref + dq_ref (t - t_k) - q) + kd (dq_ref - dq) + tau_ff - k_force tau_F,

then eq. 6 (T_m = clip(T, -T_max, T_max)); t_k is the stamp of the tick the command answers,
so between commands the position setpoint moves on with the velocity setpoint.

[resolution] tau_F, the measured foot-force torque (the (theta1, theta2) rows of J_F^T F_RF,
kinematics.foot_force_torque), is that of the ground force F_RF at the step's *start* state
under the torque of the *previous* physics step: what a force sensor sampled at the step's
start reads. The force the step itself integrates depends on T (the implicit ground damping
and the no-pull limit act on the end-of-step velocity), so taking it would be an algebraic
loop. At a control tick this is exactly the foot force of the tick's observation, so with
control at every physics step the drive-placed force loop computes PD-P&F's law of the
controller's tick (up to rounding).

A torque-only command (kp = kd = k_force = 0) gives T = tau_ff bit for bit: the same numbers
as holding the saturated torque over the period (engine.advance_prepared).
"""
from __future__ import annotations

import numpy as np
from hexapod_common.core.jit import njit

from .actuator import clip_torque
from .engine import euler_step, prepare, solve, state_ok
from hexapod_common.core.kinematics import foot_force_torque
from hexapod_common.core.layout import (C_DQREF, C_KD, C_KF, C_KP, C_QREF, C_TFF,
                                        COMMAND_FIELDS, COMMAND_SHAPE, P_DT, P_L1, P_L2,
                                        P_TMAX, Q0, V0)
from hexapod_common.core.params import N_LEGS


@njit(cache=True)
def drive_torques(cmd, s, ff, elapsed, l1, l2, t_max, demand, torque):  # type: ignore[no-untyped-def]
    """The drive law at state ``s``: unsaturated T into ``demand`` (6, 2) and T_m into
    ``torque`` (6, 2) (N m). ``ff`` (6, 2): the measured foot force (N); ``elapsed``:
    t - t_k (s); l1, l2 link lengths (m); t_max the saturation (N m)."""
    for i in range(N_LEGS):
        q1, q2 = s[Q0 + 4 * i + 2], s[Q0 + 4 * i + 3]
        tau1, tau2 = 0.0, 0.0
        if cmd[C_KF, i, 0] != 0.0 or cmd[C_KF, i, 1] != 0.0:
            tau1, tau2 = foot_force_torque(q1, q2, ff[i, 0], ff[i, 1], l1, l2)
        for j in range(2):
            q = q1 if j == 0 else q2
            dq = s[V0 + 4 * i + 2 + j]
            tau = tau1 if j == 0 else tau2
            v = (cmd[C_KP, i, j] * (cmd[C_QREF, i, j] + cmd[C_DQREF, i, j] * elapsed - q)
                 + cmd[C_KD, i, j] * (cmd[C_DQREF, i, j] - dq) + cmd[C_TFF, i, j]
                 - cmd[C_KF, i, j] * tau)
            demand[i, j] = v
            torque[i, j] = clip_torque(v, t_max)


@njit(cache=True)
def drive_advance(s, cmd, P, n_steps, fh, work, ff, qdd, demand0, torque):  # type: ignore[no-untyped-def]
    """Integrate ``n_steps`` physics steps of P[P_DT] with the drive holding ``cmd``
    (6, 6, 2), in place; the period starts at the command's tick (t - t_k = 0).

    On entry fh/work hold the state part at ``s`` and ``ff`` the foot force at ``s`` under
    the torque acting (engine.observe_prepared leaves both); ``torque`` (6, 2) is updated
    to every step's T_m and ends holding the last one. ``demand0`` gets the first step's
    unsaturated T. Returns False (and stops) as soon as the state diverges.
    """
    dt = P[P_DT]
    l1, l2, t_max = P[P_L1], P[P_L2], P[P_TMAX]
    need_force = False
    for i in range(N_LEGS):
        if cmd[C_KF, i, 0] != 0.0 or cmd[C_KF, i, 1] != 0.0:
            need_force = True
    demand = np.empty((N_LEGS, 2))
    for k in range(n_steps):
        if k > 0:
            prepare(s, P, fh, work)
            if need_force:  # the foot force at this step's start under the last torque
                solve(s, torque, P, fh, work, ff, qdd)
        drive_torques(cmd, s, ff, k * dt, l1, l2, t_max, demand, torque)
        if k == 0:
            demand0[:, :] = demand
        solve(s, torque, P, fh, work, ff, qdd)
        euler_step(s, qdd, dt)
    return state_ok(s)


def torque_only(torque: np.ndarray) -> np.ndarray:
    """A (6, 6, 2) command that applies ``torque`` (6, 2) (N m): every gain zero."""
    cmd = np.zeros(COMMAND_SHAPE)
    cmd[C_TFF] = torque
    return cmd


__all__ = ["COMMAND_FIELDS", "COMMAND_SHAPE", "C_DQREF", "C_KD", "C_KF", "C_KP", "C_QREF",
           "C_TFF", "drive_advance", "drive_torques", "torque_only"]
