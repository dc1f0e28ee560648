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
from numba import njit

from hexapod_sim.core.kinematics import foot_force_torque
from hexapod_sim.core.layout import O_FF, O_TH, O_THV
from hexapod_sim.core.params import CONTROLLERS, GainParams, check_controller

#: Integer codes of the architectures inside compiled code, in the order of CONTROLLERS.
PD_P, PD_PF = 0, 1


def controller_code(name: str) -> int:
    """'pd_p' -> PD_P, 'pd_pf' -> PD_PF (raises ParameterError otherwise)."""
    return CONTROLLERS.index(check_controller(name))


def gain_vector(g: GainParams) -> np.ndarray:
    """(Kp1, Kd1, Kp2, Kd2, K_f) as a float array for the compiled law."""
    return np.array(g.as_tuple(), dtype=float)


@njit(cache=True)
def control_law(code, gains, obs, theta_d, theta_vel_d, l1, l2, out):  # type: ignore[no-untyped-def]
    """Demanded torques T_C (6, 2) (N m) into ``out``.

    code: PD_P or PD_PF; gains: (Kp1, Kd1, Kp2, Kd2, K_f); obs: the tick's sample (9, 6, 2)
    (uses joint angles, joint rates and measured foot forces); theta_d, theta_vel_d: (6, 2)
    references (rad, rad/s); l1, l2: link lengths (m).
    """
    kf = gains[4]
    for i in range(obs.shape[1]):
        th1, th2 = obs[O_TH, i, 0], obs[O_TH, i, 1]
        tau1, tau2 = 0.0, 0.0
        if code == PD_PF:
            tau1, tau2 = foot_force_torque(th1, th2, obs[O_FF, i, 0], obs[O_FF, i, 1], l1, l2)
        g1 = gains[0] * (theta_d[i, 0] - th1) + gains[1] * (theta_vel_d[i, 0] - obs[O_THV, i, 0])
        g2 = gains[2] * (theta_d[i, 1] - th2) + gains[3] * (theta_vel_d[i, 1] - obs[O_THV, i, 1])
        out[i, 0] = kf * (g1 - tau1)
        out[i, 1] = kf * (g2 - tau2)


__all__ = ["PD_P", "PD_PF", "control_law", "controller_code", "gain_vector"]
