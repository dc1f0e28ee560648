"""Foot-ground contact: linear spring-dashpot with stored touchdown point (model.md "Ground
contact").

Foot i is in contact while y_F < 0; the touchdown point x_0 is stored at the first instant of a
contact and forgotten when the foot leaves. The ground pushes, never pulls:

    F_x = -K_gx (x_F - x_0) - B_gx dx_F
    F_y = max(0, -K_gy y_F - B_gy dy_F)

An optional Coulomb limit |F_x| <= mu F_y applies when mu > 0 (the paper has none).
The engines evaluate the damping terms at the end-of-step velocity (engine.py); this module
gives the law at a given velocity (:func:`spring_damper`), the contact state
(:func:`update_contact`) and the limits (:func:`limit_force`).
"""
from __future__ import annotations

from hexapod_common.core.jit import njit


@njit(cache=True, forceinline=True)
def update_contact(x, y, in_contact, x_touch):  # type: ignore[no-untyped-def]
    """New (in_contact, x_touch) for a foot at (x, y) (m): store x_0 at touchdown, forget it
    when the foot is at or above the ground."""
    if y >= 0.0:
        return 0.0, 0.0
    if in_contact == 0.0:
        return 1.0, x
    return 1.0, x_touch


@njit(cache=True, forceinline=True)
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


@njit(cache=True, forceinline=True)
def spring_damper(x, y, vx, vy, x_touch, kx, ky, bx, by):  # type: ignore[no-untyped-def]
    """The unlimited law of a foot in contact at (x, y) (m) moving at (vx, vy) (m/s), with
    touchdown point x_touch (m): (F_x, F_y) in N, before :func:`limit_force`.

    Both engines (engine.py, batch_physics.py) call it with the start-of-step velocity and
    add the end-of-step damping term themselves."""
    return -kx * (x - x_touch) - bx * vx, -ky * y - by * vy


__all__ = ["limit_force", "spring_damper", "update_contact"]
