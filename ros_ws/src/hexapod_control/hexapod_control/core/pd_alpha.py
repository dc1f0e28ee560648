"""PD^alpha: the fractional-order joint PD of Silva, Machado & Lopes (Nonlinear Dynamics,
2004) and Silva & Machado (J. Vibration and Control, 2006), registered as ``pd_alpha``.

Per leg and joint j, with e = theta_d - theta:  T_C = Kp_j e + Kd_j D^alpha e, 0 < alpha < 2
(alpha = 1: a PD whose derivative is the backward difference of the error). D^alpha is the
Grünwald-Letnikov series over the last M control periods T:
    D^alpha e(t_k) ~ T^-alpha sum_{i=0..M} w_i e(t_{k-i}),
    w_0 = 1, w_i = w_{i-1} (1 - (alpha + 1) / i),
with e = 0 before tick 0 (the series' convention; the run starts on the reference, e = 0).
No force feedback; the torque goes through eq. 6 (a torque-only drive command).

Written only against the public controller API (controller_api), as a user would write a
plug-in: a plain-Python (numpy) law run by the closed loop's per-tick loop.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .controller_api import Context, DriveCommand, Observation, param, torque_command


@dataclass(frozen=True)
class PdAlphaParams:
    """Gains Kp_j (N m/rad), Kd_j (N m s^alpha/rad), the order alpha and the memory M."""

    alpha: float = param("order alpha of the derivative (1 = PD)", 0.0, 2.0, lo_open=True,
                         hi_open=True, default=1.0)
    kp1: float = param("hip joint proportional gain Kp_1 (N m/rad)", 0.0, 1e9, default=1e5)
    kd1: float = param("hip joint derivative gain Kd_1 (N m s^alpha/rad)", 0.0, 1e9,
                       default=250.0)
    kp2: float = param("knee joint proportional gain Kp_2 (N m/rad)", 0.0, 1e9, default=1.2e5)
    kd2: float = param("knee joint derivative gain Kd_2 (N m s^alpha/rad)", 0.0, 1e9,
                       default=50.0)
    memory: int = param("Grünwald-Letnikov memory M (control periods)", 1, 100000,
                        kind=int, default=200)


def gl_weights(alpha: float, memory: int) -> np.ndarray:
    """Grünwald-Letnikov weights w_0..w_M of order ``alpha`` (w_0 = 1)."""
    w = np.empty(memory + 1)
    w[0] = 1.0
    for i in range(1, memory + 1):
        w[i] = w[i - 1] * (1.0 - (alpha + 1.0) / i)
    return w


class PdAlpha:
    """Kp e + Kd D^alpha e per joint, D^alpha by a Grünwald-Letnikov series."""

    Params = PdAlphaParams

    def __init__(self, params: PdAlphaParams, context: Context) -> None:
        self.params = params
        self.kp = np.array([params.kp1, params.kp2])
        self.kd = np.array([params.kd1, params.kd2])
        # weights already scaled by T^-alpha, to contract the history with
        self.weights = gl_weights(params.alpha, params.memory) * \
            context.control_period ** -params.alpha
        # e of the last M + 1 ticks, newest first, one row of the 12 joints each
        self.history = np.zeros((params.memory + 1, 12))

    def reset(self) -> None:
        """Forget the error history (e = 0 before the next tick)."""
        self.history[:] = 0.0

    def law(self, obs: Observation) -> DriveCommand:
        """Torque-only command Kp e + Kd D^alpha e (N m)."""
        e = obs.theta_d - obs.theta
        h = self.history
        h[1:] = h[:-1]
        h[0] = e.ravel()
        d_alpha = (self.weights @ h).reshape(e.shape)  # (a vector-matrix product: ~2 us)
        return torque_command(self.kp * e + self.kd * d_alpha)


__all__ = ["PdAlpha", "PdAlphaParams", "gl_weights"]
