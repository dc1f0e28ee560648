"""Compliant body: segments linked by spring-dashpots along x and y (model.md "Body compliance").

[resolution: topology] Links join each left-right pair (1-2, 3-4, 5-6) and each front-rear
neighbour on one side (1-3, 3-5, 2-4, 4-6). For a link (a, b) the force on a is

    F_x = K_bx (x_b - x_a - (x0_b - x0_a)) + B_bx (dx_b - dx_a)
    F_y = K_by (y_b - y_a) + B_by (dy_b - dy_a)

and the opposite force acts on b. Legs are 0-based here.
"""
from __future__ import annotations

import numpy as np
from hexapod_common.core.jit import njit

from hexapod_common.core.layout import P_BBX, P_BBY, P_HIPX, P_KBX, P_KBY, Q0, V0
from hexapod_common.core.params import N_LEGS

LINKS = np.array([[0, 1], [2, 3], [4, 5], [0, 2], [2, 4], [1, 3], [3, 5]], dtype=np.int64)


@njit(cache=True, forceinline=True)
def link_force(xa, ya, vxa, vya, xb, yb, vxb, vyb, x0a, x0b, kx, ky, bx,  # type: ignore[no-untyped-def]
               by):
    """Force (N) of the link (a, b) on hip a (hip b feels the opposite): hips at (xa, ya),
    (xb, yb) (m) moving at (vxa, vya), (vxb, vyb) (m/s), nominal x offsets x0a, x0b (m)."""
    fx = kx * (xb - xa - (x0b - x0a)) + bx * (vxb - vxa)
    fy = ky * (yb - ya) + by * (vyb - vya)
    return fx, fy


@njit(cache=True, inline="always")
def body_forces(s, P, out):  # type: ignore[no-untyped-def]
    """Sum of link forces on each hip segment, F_RH (N), written into ``out`` (6, 2).

    s: a state vector (hip positions and rates at layout.Q0 / V0, leg-major); P: the model
    vector (gains P_KBX..P_BBY, nominal hip x offsets from P_HIPX, m). Read by index, and
    inlined into the engine's step: views of the state or calls with array arguments cost an
    atomic reference count each, which was ~40 % of a physics step.
    """
    for i in range(N_LEGS):
        out[i, 0] = 0.0
        out[i, 1] = 0.0
    kx, ky, bx, by = P[P_KBX], P[P_KBY], P[P_BBX], P[P_BBY]
    for k in range(LINKS.shape[0]):
        a, b = LINKS[k, 0], LINKS[k, 1]
        qa, qb, va, vb = Q0 + 4 * a, Q0 + 4 * b, V0 + 4 * a, V0 + 4 * b
        fx, fy = link_force(s[qa], s[qa + 1], s[va], s[va + 1], s[qb], s[qb + 1], s[vb],
                            s[vb + 1], P[P_HIPX + a], P[P_HIPX + b], kx, ky, bx, by)
        out[a, 0] += fx
        out[a, 1] += fy
        out[b, 0] -= fx
        out[b, 1] -= fy
