"""Actuator saturation (paper eq. 6): T_m = clip(T_C, -T_max, +T_max); T_max = inf is ideal."""
from __future__ import annotations

from hexapod_common.core.jit import njit


@njit(cache=True, forceinline=True)
def clip_torque(v, t_max):  # type: ignore[no-untyped-def]
    """clip(v, -t_max, t_max) of one joint torque (N m)."""
    if v > t_max:
        v = t_max
    elif v < -t_max:
        v = -t_max
    return v


@njit(cache=True)
def saturate(demand, t_max, out):  # type: ignore[no-untyped-def]
    """Write clip(demand, -t_max, t_max) into ``out``; both (6, 2) arrays of joint torques (N m)."""
    for i in range(demand.shape[0]):
        for j in range(demand.shape[1]):
            out[i, j] = clip_torque(demand[i, j], t_max)
