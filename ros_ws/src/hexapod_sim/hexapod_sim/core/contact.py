"""Foot-ground contact: linear spring-dashpot with stored touchdown point (model.md "Ground contact").

Foot i is in contact while y_F < 0; the touchdown point x_0 is stored at the first instant of a
contact and forgotten when the foot leaves. The ground pushes, never pulls:

    F_x = -K_gx (x_F - x_0) - B_gx dx_F
    F_y = max(0, -K_gy y_F - B_gy dy_F)

An optional Coulomb limit |F_x| <= mu F_y applies when mu > 0 (the paper has none).
"""
from __future__ import annotations

from numba import njit


@njit(cache=True)
def ground_force(x, y, vx, vy, in_contact, x_touch, kx, ky, bx, by,  # type: ignore[no-untyped-def]
                 mu):
    """Ground reaction on one foot and the updated contact state.

    (x, y), (vx, vy): foot position (m) and velocity (m/s); in_contact (0/1) and x_touch (m):
    the stored contact state. Returns (F_x, F_y, in_contact, x_touch) in N, N, -, m.
    """
    if y >= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    if in_contact == 0.0:
        x_touch = x
    fx = -kx * (x - x_touch) - bx * vx
    fy = -ky * y - by * vy
    if fy < 0.0:
        fy = 0.0
    if mu > 0.0:
        lim = mu * fy
        if fx > lim:
            fx = lim
        elif fx < -lim:
            fx = -lim
    return fx, fy, 1.0, x_touch
