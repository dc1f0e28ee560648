"""Foot-ground contact: linear spring-dashpot with stored touchdown point (model.md "Ground
contact").

Foot i is in contact while y_F < 0; the touchdown point x_0 is stored at the first instant of a
contact and forgotten when the foot leaves. The ground pushes, never pulls:

    F_x = -K_gx (x_F - x_0) - B_gx dx_F
    F_y = max(0, -K_gy y_F - B_gy dy_F)

An optional Coulomb limit |F_x| <= mu F_y applies when mu > 0 (the paper has none).
The engine evaluates the damping terms at the end-of-step velocity (engine.py); this module
gives the law at a given velocity.
"""
from __future__ import annotations

from numba import njit


@njit(cache=True)
def update_contact(x, y, in_contact, x_touch):  # type: ignore[no-untyped-def]
    """New (in_contact, x_touch) for a foot at (x, y) (m): store x_0 at touchdown, forget it
    when the foot is at or above the ground."""
    if y >= 0.0:
        return 0.0, 0.0
    if in_contact == 0.0:
        return 1.0, x
    return 1.0, x_touch


@njit(cache=True)
def limit_force(fx, fy, mu):  # type: ignore[no-untyped-def]
    """Apply 'the ground never pulls' and, if mu > 0, the Coulomb limit |F_x| <= mu F_y."""
    if fy < 0.0:
        fy = 0.0
    if mu > 0.0:
        lim = mu * fy
        if fx > lim:
            fx = lim
        elif fx < -lim:
            fx = -lim
    return fx, fy


@njit(cache=True)
def ground_force(x, y, vx, vy, in_contact, x_touch, kx, ky, bx, by,  # type: ignore[no-untyped-def]
                 mu):
    """Ground reaction on one foot at velocity (vx, vy) and the updated contact state.

    (x, y): foot position (m); in_contact (0/1) and x_touch (m): the stored contact state.
    Returns (F_x, F_y, in_contact, x_touch) in N, N, -, m.
    """
    c, xt = update_contact(x, y, in_contact, x_touch)
    if c == 0.0:
        return 0.0, 0.0, 0.0, 0.0
    fx, fy = limit_force(-kx * (x - xt) - bx * vx, -ky * y - by * vy, mu)
    return fx, fy, c, xt
