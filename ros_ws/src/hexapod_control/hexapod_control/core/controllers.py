"""Joint controllers PD-P and PD-P&F (paper eq. 7 and Fig. 3).

Per leg and joint j: e = theta_d - theta, de = dtheta_d - dtheta, G_c1 = Kp_j e + Kd_j de.

- PD-P:    T_C = K_f G_c1                      (no force feedback; K_f = 1.0 in Table I)
- PD-P&F:  T_C = K_f (G_c1 - tau_F)            [resolution of the lost Fig. 3, model.md]
  tau_F = the (theta1, theta2) rows of J_F^T F_RF: the joint torque produced by the measured
  foot force. In transfer F_RF = 0 and the law reduces to K_f G_c1 (K_f = 0.9 in Table I).

The output is the *demanded* torque T_C; saturation (eq. 6) belongs to the actuator model.
"""
from __future__ import annotations

import numpy as np
from hexapod_common.core.jit import njit

from hexapod_common.core.kinematics import foot_force_torque
from hexapod_common.core.layout import (C_DQREF, C_KD, C_KF, C_KP, C_QREF, C_TFF, O_FF, O_TH,
                                        O_THV)
from hexapod_common.core.errors import ParameterError
from hexapod_common.core.params import CONTROLLERS, GainParams, check_controller

#: Integer codes of the architectures inside compiled code, in the order of CONTROLLERS.
PD_P, PD_PF = 0, 1
#: Batch-only code: PD-P&F with its force loop in the drive (batch_loop evaluates the drive
#: at every physics step; single runs use hexapod_sim.core.drive).
PD_PF_DRIVE = 2


def controller_code(name: str) -> int:
    """'pd_p' -> PD_P, 'pd_pf' -> PD_PF (raises ParameterError for any other name: only
    the built-ins have a compiled law)."""
    name = check_controller(name)
    if name not in CONTROLLERS:
        raise ParameterError("run.controller", name, "a controller with a compiled law (one "
                             "of " + ", ".join(CONTROLLERS) + ")")
    return CONTROLLERS.index(name)


def gain_vector(g: GainParams) -> np.ndarray:
    """(Kp1, Kd1, Kp2, Kd2, K_f) as a float array for the compiled law."""
    return np.array(g.as_tuple(), dtype=float)


@njit(cache=True, forceinline=True)
def leg_demand(code, kp1, kd1, kp2, kd2, kf, th1, th2, w1, w2, ffx, ffy,  # type: ignore[no-untyped-def]
               thd1, thd2, wd1, wd2, l1, l2):
    """Demanded torques (T_C1, T_C2) (N m) of one leg: joint angles th (rad) and rates w
    (rad/s), measured foot force (ffx, ffy) (N, used by PD_PF), references thd, wd."""
    tau1, tau2 = 0.0, 0.0
    if code == PD_PF:
        tau1, tau2 = foot_force_torque(th1, th2, ffx, ffy, l1, l2)
    g1 = kp1 * (thd1 - th1) + kd1 * (wd1 - w1)
    g2 = kp2 * (thd2 - th2) + kd2 * (wd2 - w2)
    return kf * (g1 - tau1), kf * (g2 - tau2)


@njit(cache=True)
def control_law(code, gains, obs, theta_d, theta_vel_d, l1, l2, out):  # type: ignore[no-untyped-def]
    """Demanded torques T_C (6, 2) (N m) into ``out``.

    code: PD_P or PD_PF; gains: (Kp1, Kd1, Kp2, Kd2, K_f); obs: the tick's sample (9, 6, 2)
    (uses joint angles, joint rates and measured foot forces); theta_d, theta_vel_d: (6, 2)
    references (rad, rad/s); l1, l2: link lengths (m).
    """
    for i in range(obs.shape[1]):
        out[i, 0], out[i, 1] = leg_demand(
            code, gains[0], gains[1], gains[2], gains[3], gains[4], obs[O_TH, i, 0],
            obs[O_TH, i, 1], obs[O_THV, i, 0], obs[O_THV, i, 1], obs[O_FF, i, 0],
            obs[O_FF, i, 1], theta_d[i, 0], theta_d[i, 1], theta_vel_d[i, 0],
            theta_vel_d[i, 1], l1, l2)


@njit(cache=True)
def pd_pf_drive_command(gains, theta_d, theta_vel_d, cmd):  # type: ignore[no-untyped-def]
    """PD-P&F with its force loop in the drive (model.md "Drive interface"): the drive
    command (6, 6, 2) into ``cmd``: q_ref, dq_ref the references (rad, rad/s), kp = K_f Kp,
    kd = K_f Kd, tau_ff = 0, k_force = K_f. gains: (Kp1, Kd1, Kp2, Kd2, K_f)."""
    kf = gains[4]
    for i in range(theta_d.shape[0]):
        for m in range(2):
            cmd[C_QREF, i, m] = theta_d[i, m]
            cmd[C_DQREF, i, m] = theta_vel_d[i, m]
            cmd[C_KP, i, m] = kf * gains[2 * m]
            cmd[C_KD, i, m] = kf * gains[2 * m + 1]
            cmd[C_TFF, i, m] = 0.0
            cmd[C_KF, i, m] = kf


__all__ = ["PD_P", "PD_PF", "PD_PF_DRIVE", "control_law", "controller_code", "gain_vector",
           "leg_demand", "pd_pf_drive_command"]
