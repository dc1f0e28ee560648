"""Many states stepped at once, the case index innermost (structure of arrays).

A block of B cases keeps each state row of layout.py as one contiguous row of B values:
``X`` (STATE_SIZE, B), the model vectors ``PT`` (MODEL_SIZE, B), torques ``TQ`` (12, B)
(row 2 i + j: leg i, joint j). Each loop over the cases of a block calls the engine's own
scalar equations (body.link_force, contact.update_contact / limit_force,
dynamics.leg_system_cs / leg_solve, engine.leg_sample), so LLVM vectorises them across
cases and every case gets the single-run engine's numbers. Branches of the single run
become selects of the same operands; cos/sin run in a loop of their own (libm, as in the
single run); the rare re-solve of a leg whose ground force hits a limit runs in a scalar
pass after the vector loop. Only the first ``n`` columns are stepped: a caller drops a
diverged case by swapping it behind them (:func:`swap_columns`).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .body import LINKS, link_force
from .contact import limit_force, update_contact
from .dynamics import leg_accel_cs, leg_solve, leg_system_cs
from .engine import W_BIAS, W_CS, W_FACTOR, W_FG, W_JAC, W_SIZE, W_W, leg_sample
from .kinematics import foot_offset_cs, foot_velocity_cs
from .layout import (C0, P_BBX, P_BBY, P_BGX, P_BGY, P_DT, P_G, P_HIPX, P_IMPL, P_KBX, P_KBY,
                     P_KGX, P_KGY, P_L1, P_L2, P_MF, P_MH, P_MK, P_MU, Q0, V0, X0)
from .params import N_LEGS


@njit(cache=True)
def block_scratch(B):  # type: ignore[no-untyped-def]
    """Work arrays of a block of B cases: (FH (12, B), WK (6, W_SIZE, B), FF (12, B),
    QDD (24, B), TR (4, B) cos/sin, FLAG (B,) legs to re-solve)."""
    return (np.empty((2 * N_LEGS, B)), np.empty((N_LEGS, W_SIZE, B)),
            np.empty((2 * N_LEGS, B)), np.empty((4 * N_LEGS, B)), np.empty((4, B)),
            np.zeros(B))


@njit(cache=True, error_model="numpy")
def block_prepare(X, PT, n, FH, WK, TR):  # type: ignore[no-untyped-def]
    """engine.prepare for columns 0..n-1: contact update in X, F_RH into FH, the legs'
    state part into WK."""
    for r in range(2 * N_LEGS):
        for b in range(n):
            FH[r, b] = 0.0
    for k in range(LINKS.shape[0]):
        la, lb = LINKS[k, 0], LINKS[k, 1]
        for b in range(n):
            fx, fy = link_force(X[Q0 + 4 * la, b], X[Q0 + 4 * la + 1, b], X[V0 + 4 * la, b],
                                X[V0 + 4 * la + 1, b], X[Q0 + 4 * lb, b],
                                X[Q0 + 4 * lb + 1, b], X[V0 + 4 * lb, b],
                                X[V0 + 4 * lb + 1, b], PT[P_HIPX + la, b], PT[P_HIPX + lb, b],
                                PT[P_KBX, b], PT[P_KBY, b], PT[P_BBX, b], PT[P_BBY, b])
            FH[2 * la, b] += fx
            FH[2 * la + 1, b] += fy
            FH[2 * lb, b] -= fx
            FH[2 * lb + 1, b] -= fy
    for i in range(N_LEGS):
        for b in range(n):
            th1 = X[Q0 + 4 * i + 2, b]
            th12 = th1 + X[Q0 + 4 * i + 3, b]
            TR[0, b] = np.cos(th1)
            TR[1, b] = np.sin(th1)
            TR[2, b] = np.cos(th12)
            TR[3, b] = np.sin(th12)
        for b in range(n):
            c1, s1, c12, s12 = TR[0, b], TR[1, b], TR[2, b], TR[3, b]
            w1, w2 = X[V0 + 4 * i + 2, b], X[V0 + 4 * i + 3, b]
            l1, l2 = PT[P_L1, b], PT[P_L2, b]
            dx, dy = foot_offset_cs(c1, s1, c12, s12, l1, l2)
            x, y = X[Q0 + 4 * i, b] + dx, X[Q0 + 4 * i + 1, b] + dy
            c, xt = update_contact(x, y, X[C0 + i, b], X[X0 + i, b])
            X[C0 + i, b] = c
            X[X0 + i, b] = xt
            dvx, dvy = foot_velocity_cs(c1, s1, c12, s12, w1, w2, l1, l2)
            vx, vy = X[V0 + 4 * i, b] + dvx, X[V0 + 4 * i + 1, b] + dvy
            bx, by = PT[P_BGX, b], PT[P_BGY, b]
            fx = -PT[P_KGX, b] * (x - xt) - bx * vx
            fy = -PT[P_KGY, b] * y - by * vy
            h = PT[P_DT, b] if PT[P_IMPL, b] != 0.0 else 0.0
            if c == 0.0:  # in flight: no ground force, the plain solve (engine.prepare)
                fx, fy, bx, by, h = 0.0, 0.0, 0.0, 0.0, 0.0
            factor, bias, jac = leg_system_cs(c1, s1, c12, s12, w1, w2, l1, l2, PT[P_MH, b],
                                              PT[P_MK, b], PT[P_MF, b], PT[P_G, b], bx, by, h)
            for k in range(10):
                WK[i, W_FACTOR + k, b] = factor[k]
            for k in range(4):
                WK[i, W_BIAS + k, b] = bias[k]
                WK[i, W_JAC + k, b] = jac[k]
            WK[i, W_FG, b] = fx
            WK[i, W_FG + 1, b] = fy
            WK[i, W_CS, b] = c1
            WK[i, W_CS + 1, b] = s1
            WK[i, W_CS + 2, b] = c12
            WK[i, W_CS + 3, b] = s12
            WK[i, W_W, b] = w1
            WK[i, W_W + 1, b] = w2


@njit(cache=True, error_model="numpy")
def block_solve(X, TQ, PT, n, FH, WK, FF, QDD, FLAG):  # type: ignore[no-untyped-def]
    """engine.solve for columns 0..n-1: F_RF into FF, ddq into QDD under torques TQ."""
    for i in range(N_LEGS):
        any_limited = False
        for b in range(n):
            factor = (WK[i, 0, b], WK[i, 1, b], WK[i, 2, b], WK[i, 3, b], WK[i, 4, b],
                      WK[i, 5, b], WK[i, 6, b], WK[i, 7, b], WK[i, 8, b], WK[i, 9, b])
            bias = (WK[i, W_BIAS, b], WK[i, W_BIAS + 1, b], WK[i, W_BIAS + 2, b],
                    WK[i, W_BIAS + 3, b])
            af, bf, ja2, jb2 = (WK[i, W_JAC, b], WK[i, W_JAC + 1, b], WK[i, W_JAC + 2, b],
                                WK[i, W_JAC + 3, b])
            fx0, fy0 = WK[i, W_FG, b], WK[i, W_FG + 1, b]
            a0, a1, a2, a3 = leg_solve(factor, bias, (af, bf, ja2, jb2), TQ[2 * i, b],
                                       TQ[2 * i + 1, b], FH[2 * i, b], FH[2 * i + 1, b],
                                       fx0, fy0)
            # engine.leg_contact_solve: ground damping at the end-of-step velocity, limits
            h = PT[P_DT, b] if PT[P_IMPL, b] != 0.0 else 0.0
            fx, fy = fx0, fy0
            if h > 0.0:
                fx = fx0 - PT[P_BGX, b] * (h * (a0 + af * a2 + ja2 * a3))
                fy = fy0 - PT[P_BGY, b] * (h * (a1 + bf * a2 + jb2 * a3))
            lx, ly = limit_force(fx, fy, PT[P_MU, b])
            contact = X[C0 + i, b] != 0.0
            limited = contact and (lx != fx or ly != fy)
            if not contact:
                lx, ly = 0.0, 0.0
            FF[2 * i, b] = lx
            FF[2 * i + 1, b] = ly
            QDD[4 * i, b] = a0
            QDD[4 * i + 1, b] = a1
            QDD[4 * i + 2, b] = a2
            QDD[4 * i + 3, b] = a3
            FLAG[b] = 1.0 if limited else 0.0
            any_limited |= limited
        if any_limited:
            for b in range(n):
                if FLAG[b] != 0.0:
                    r = leg_accel_cs(WK[i, W_CS, b], WK[i, W_CS + 1, b], WK[i, W_CS + 2, b],
                                     WK[i, W_CS + 3, b], WK[i, W_W, b], WK[i, W_W + 1, b],
                                     PT[P_L1, b], PT[P_L2, b], PT[P_MH, b], PT[P_MK, b],
                                     PT[P_MF, b], PT[P_G, b], TQ[2 * i, b], TQ[2 * i + 1, b],
                                     FH[2 * i, b], FH[2 * i + 1, b], FF[2 * i, b],
                                     FF[2 * i + 1, b], 0.0, 0.0, 0.0)
                    for j in range(4):
                        QDD[4 * i + j, b] = r[j]


@njit(cache=True)
def block_integrate(X, PT, n, QDD):  # type: ignore[no-untyped-def]
    """engine.advance_prepared's update: dq += dt ddq, then q += dt dq (columns 0..n-1)."""
    for r in range(4 * N_LEGS):
        for b in range(n):
            dt = PT[P_DT, b]
            v = X[V0 + r, b] + dt * QDD[r, b]
            X[V0 + r, b] = v
            X[Q0 + r, b] += dt * v


@njit(cache=True)
def block_sample(X, TQ, PT, b, FH, WK, FF, QDD, obs):  # type: ignore[no-untyped-def]
    """engine.observe_prepared's sample of column b (after block_prepare and block_solve
    with the held torque) into ``obs`` (9, 6, 2)."""
    for i in range(N_LEGS):
        sample = leg_sample(X[Q0 + 4 * i, b], X[Q0 + 4 * i + 1, b], X[Q0 + 4 * i + 2, b],
                            X[Q0 + 4 * i + 3, b], X[V0 + 4 * i, b], X[V0 + 4 * i + 1, b],
                            X[V0 + 4 * i + 2, b], X[V0 + 4 * i + 3, b], WK[i, W_CS, b],
                            WK[i, W_CS + 1, b], WK[i, W_CS + 2, b], WK[i, W_CS + 3, b],
                            TQ[2 * i, b], TQ[2 * i + 1, b], FF[2 * i, b], FF[2 * i + 1, b],
                            QDD[4 * i, b], QDD[4 * i + 1, b], FH[2 * i, b], FH[2 * i + 1, b],
                            PT[P_L1, b], PT[P_L2, b], PT[P_MH, b], PT[P_G, b])
        for f in range(9):
            obs[f, i, 0] = sample[2 * f]
            obs[f, i, 1] = sample[2 * f + 1]


@njit(cache=True)
def swap_columns(A, a, b):  # type: ignore[no-untyped-def]
    """Swap columns a and b of a 2-D array in place."""
    for r in range(A.shape[0]):
        A[r, a], A[r, b] = A[r, b], A[r, a]


__all__ = ["block_integrate", "block_prepare", "block_sample", "block_scratch", "block_solve",
           "swap_columns"]
