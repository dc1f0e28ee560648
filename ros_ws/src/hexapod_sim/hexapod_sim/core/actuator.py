"""Actuator saturation (paper eq. 6): T_m = clip(T_C, -T_max, +T_max); T_max = inf is ideal."""
from __future__ import annotations

from numba import njit


@njit(cache=True)
def saturate(demand, t_max, out):  # type: ignore[no-untyped-def]
    """Write clip(demand, -t_max, t_max) into ``out``; both (6, 2) arrays of joint torques (N m)."""
    for i in range(demand.shape[0]):
        for j in range(demand.shape[1]):
            v = demand[i, j]
            if v > t_max:
                v = t_max
            elif v < -t_max:
                v = -t_max
            out[i, j] = v
