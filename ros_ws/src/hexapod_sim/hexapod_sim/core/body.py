"""Compliant body: segments linked by spring-dashpots along x and y (model.md "Body compliance").

[resolution: topology] Links join each left-right pair (1-2, 3-4, 5-6) and each front-rear
neighbour on one side (1-3, 3-5, 2-4, 4-6). For a link (a, b) the force on a is

    F_x = K_bx (x_b - x_a - (x0_b - x0_a)) + B_bx (dx_b - dx_a)
    F_y = K_by (y_b - y_a) + B_by (dy_b - dy_a)

and the opposite force acts on b. Legs are 0-based here.
"""
from __future__ import annotations

import numpy as np
from numba import njit

LINKS = np.array([[0, 1], [2, 3], [4, 5], [0, 2], [2, 4], [1, 3], [3, 5]], dtype=np.int64)


@njit(cache=True)
def link_force(xa, ya, vxa, vya, xb, yb, vxb, vyb, x0a, x0b, kx, ky, bx,  # type: ignore[no-untyped-def]
               by):
    """Force (N) of the link (a, b) on hip a (hip b feels the opposite): hips at (xa, ya),
    (xb, yb) (m) moving at (vxa, vya), (vxb, vyb) (m/s), nominal x offsets x0a, x0b (m)."""
    fx = kx * (xb - xa - (x0b - x0a)) + bx * (vxb - vxa)
    fy = ky * (yb - ya) + by * (vyb - vya)
    return fx, fy


@njit(cache=True)
def body_forces(q, dq, hip_x0, kx, ky, bx, by, out):  # type: ignore[no-untyped-def]
    """Sum of link forces on each hip segment, F_RH (N), written into ``out`` (6, 2).

    q, dq: (6, 4) leg coordinates and rates; hip_x0: (6,) nominal hip offsets (m).
    """
    out[:, :] = 0.0
    for k in range(LINKS.shape[0]):
        a, b = LINKS[k, 0], LINKS[k, 1]
        fx, fy = link_force(q[a, 0], q[a, 1], dq[a, 0], dq[a, 1], q[b, 0], q[b, 1], dq[b, 0],
                            dq[b, 1], hip_x0[a], hip_x0[b], kx, ky, bx, by)
        out[a, 0] += fx
        out[a, 1] += fy
        out[b, 0] -= fx
        out[b, 1] -= fy
