"""The additive sums of the seven indices (paper eqs. 8-11), one sample at a time, compiled.

This is the one implementation of the sums: ``hexapod_metrics.core.indices.window_sums``
(the metrics node, ``hexapod analyze``, the single-run engine) runs :func:`accumulate` over
recorded samples, and the batched engine (``hexapod_control.core.batch_loop``) calls
:func:`start_window` and :func:`add_sample` at every tick of a case's evaluation window, so
a sweep scores its cases without recording them. Both add the samples in the same order, so
they agree to the last bit.

Accumulator ``acc`` (float64, length :data:`ACC_SIZE`), per window of samples 0..N (row 0
only supplies x_iH(t_a); the sums run over samples 1..N):

    acc[A_ENERGY]         sum |T_mij dtheta_ij|             (N m rad/s; x Delta t -> J)
    acc[A_TORQUE2]        sum T_mij^2                        (N^2 m^2)
    acc[A_FORCE2]         sum f_ix^2 + f_iy^2                (N^2)
    acc[A_SQ:A_SQ+24]     per leg sums of squared errors of x_H, y_H, x_F, y_F (m^2), (4, 6)
    acc[A_LAG]            sum of x_iHd - x_iH over samples and legs (m)
    acc[A_X0:A_X0+6]      x_iH(t_a) per leg (m)
    acc[A_X1:A_X1+6]      x_iH of the last sample added (m)
    acc[A_SAMPLES]        N, the samples added
    acc[A_EX:A_EX+12]     per leg sums of the horizontal errors x_iHd - x_iH, x_iFd - x_iF
                          (m), (2, 6): each leg's mean offset over the window
    acc[A_E0:A_E0+12]     those errors at row 0, t_a (m), (2, 6)
    acc[A_E1:A_E1+12]     those errors at the last sample added (m), (2, 6): with A_E0, the
                          drift of the window (model docs, "Drift and tracking")
    acc[A_HY_MIN]         lowest hip height y_iH over samples and legs (m)
    acc[A_HY_MAX]         highest hip height (m)
    acc[A_FY_MIN]         lowest foot height y_iF (m): with the two above, whether the
                          window was a walk (hexapod_metrics.core.walking)
"""
from __future__ import annotations

import numpy as np
from .jit import njit

from .robot import N_LEGS

A_ENERGY, A_TORQUE2, A_FORCE2, A_SQ = 0, 1, 2, 3
A_LAG = A_SQ + 4 * N_LEGS
A_X0 = A_LAG + 1
A_X1 = A_X0 + N_LEGS
A_SAMPLES = A_X1 + N_LEGS
A_EX = A_SAMPLES + 1
A_E0 = A_EX + 2 * N_LEGS
A_E1 = A_E0 + 2 * N_LEGS
A_HY_MIN = A_E1 + 2 * N_LEGS
A_HY_MAX = A_HY_MIN + 1
A_FY_MIN = A_HY_MAX + 1
ACC_SIZE = A_FY_MIN + 1


@njit(cache=True)
def start_window(acc, hip_pos, hip_ref, foot_pos, foot_ref):  # type: ignore[no-untyped-def]
    """Reset ``acc`` for a window whose row 0 has hip and foot positions and references
    ``hip_pos``, ``hip_ref``, ``foot_pos``, ``foot_ref`` (6, 2) (m, world frame)."""
    acc[:] = 0.0
    acc[A_HY_MIN] = np.inf
    acc[A_HY_MAX] = -np.inf
    acc[A_FY_MIN] = np.inf
    for i in range(N_LEGS):
        acc[A_X0 + i] = hip_pos[i, 0]
        acc[A_X1 + i] = hip_pos[i, 0]
        exh = hip_ref[i, 0] - hip_pos[i, 0]
        exf = foot_ref[i, 0] - foot_pos[i, 0]
        acc[A_E0 + i] = exh
        acc[A_E0 + N_LEGS + i] = exf
        acc[A_E1 + i] = exh
        acc[A_E1 + N_LEGS + i] = exf


@njit(cache=True)
def add_sample(acc, torque, joint_vel, hip_force, hip_pos, hip_ref, foot_pos,  # type: ignore[no-untyped-def]
               foot_ref):
    """Add one sample (every argument (6, 2): T_m N m, dtheta rad/s, f_i N, p_H, p_Hd,
    p_F, p_Fd m, world frame) to ``acc``."""
    for i in range(N_LEGS):
        for j in range(2):
            tq = torque[i, j]
            acc[A_ENERGY] += abs(tq * joint_vel[i, j])
            acc[A_TORQUE2] += tq * tq
            f = hip_force[i, j]
            acc[A_FORCE2] += f * f
        exh = hip_ref[i, 0] - hip_pos[i, 0]
        eyh = hip_ref[i, 1] - hip_pos[i, 1]
        exf = foot_ref[i, 0] - foot_pos[i, 0]
        eyf = foot_ref[i, 1] - foot_pos[i, 1]
        acc[A_SQ + i] += exh * exh
        acc[A_SQ + N_LEGS + i] += eyh * eyh
        acc[A_SQ + 2 * N_LEGS + i] += exf * exf
        acc[A_SQ + 3 * N_LEGS + i] += eyf * eyf
        acc[A_LAG] += exh
        acc[A_X1 + i] = hip_pos[i, 0]
        acc[A_EX + i] += exh
        acc[A_EX + N_LEGS + i] += exf
        acc[A_E1 + i] = exh
        acc[A_E1 + N_LEGS + i] = exf
        acc[A_HY_MIN] = min(acc[A_HY_MIN], hip_pos[i, 1])
        acc[A_HY_MAX] = max(acc[A_HY_MAX], hip_pos[i, 1])
        acc[A_FY_MIN] = min(acc[A_FY_MIN], foot_pos[i, 1])
    acc[A_SAMPLES] += 1.0


@njit(cache=True)
def accumulate(acc, torque, joint_vel, hip_force, hip_pos, hip_ref, foot_pos,  # type: ignore[no-untyped-def]
               foot_ref):
    """``acc`` of a whole window: (N+1, 6, 2) arrays as in :func:`add_sample`, row 0 only
    supplying x_iH(t_a)."""
    start_window(acc, hip_pos[0], hip_ref[0], foot_pos[0], foot_ref[0])
    for r in range(1, hip_pos.shape[0]):
        add_sample(acc, torque[r], joint_vel[r], hip_force[r], hip_pos[r], hip_ref[r],
                   foot_pos[r], foot_ref[r])


def new_accumulator() -> np.ndarray:
    """A zeroed accumulator (float64, :data:`ACC_SIZE`)."""
    return np.zeros(ACC_SIZE)


__all__ = ["ACC_SIZE", "A_E0", "A_E1", "A_ENERGY", "A_EX",
           "A_FORCE2", "A_FY_MIN", "A_HY_MAX", "A_HY_MIN", "A_LAG", "A_SAMPLES", "A_SQ",
           "A_TORQUE2",
           "A_X0", "A_X1", "accumulate", "add_sample", "new_accumulator", "start_window"]
