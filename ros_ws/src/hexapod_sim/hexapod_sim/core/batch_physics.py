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
from hexapod_common.core.jit import njit

from .body import LINKS, link_force
from .contact import limit_force, spring_damper, update_contact
from .dynamics import leg_accel_cs, leg_solve, leg_system_cs
from .sincos import cos_sin
from .engine import W_BIAS, W_CS, W_FACTOR, W_FG, W_JAC, W_SIZE, W_W, leg_sample
from hexapod_common.core.kinematics import foot_offset_cs, foot_velocity_cs
from hexapod_common.core.layout import (C0, P_BBX, P_BBY, P_BGX, P_BGY, P_DT, P_G, P_HIPX, P_IMPL,
                                        P_KBX, P_KBY, P_KGX, P_KGY, P_L1, P_L2, P_MF, P_MH, P_MK,
                                        P_MU, Q0, V0, X0)
from hexapod_common.core.params import N_LEGS

#: Columns of every block array. A compile-time row length lets LLVM see that the rows of
#: one array never overlap, so the loops over cases vectorise with a few alias checks.
LANES = 64

#: body.LINKS as unsigned bytes: row indices that LLVM knows are >= 0 need no wraparound
#: select (numba's negative-index handling), which would stop the loops over cases from
#: vectorising.
LINK_HIPS = LINKS.astype(np.uint8)


@njit(cache=True)
def block_scratch():  # type: ignore[no-untyped-def]
    """Work arrays of a block, B = LANES: (FH (12, B), WK (6, W_SIZE, B), FF (12, B),
    QDD (24, B), TR (14, B) the body links' forces, then a leg's contact state, FLAG (B,)
    legs to re-solve)."""
    B = LANES
    return (np.empty((2 * N_LEGS, B)), np.empty((N_LEGS, W_SIZE, B)),
            np.empty((2 * N_LEGS, B)), np.empty((4 * N_LEGS, B)),
            np.empty((2 * LINKS.shape[0], B)), np.zeros(B))


@njit(cache=True)
def _flat(A):  # type: ignore[no-untyped-def]
    """A C-contiguous block array as one row (element [r, b] at r * LANES + b)."""
    return A.reshape(A.size)


@njit(cache=True, error_model="numpy")
def block_prepare(X, PT, n, FH, WK, TR):  # type: ignore[no-untyped-def]
    """engine.prepare for columns 0..n-1: contact update in X, F_RH into FH, the legs'
    state part into WK."""
    x, pt, fh, wk, tr = _flat(X), _flat(PT), _flat(FH), _flat(WK), _flat(TR)
    L = LANES
    for k in range(LINK_HIPS.shape[0]):  # each link's force on its first hip, into tr
        la, lb = LINK_HIPS[k, 0], LINK_HIPS[k, 1]
        qa, va, qb, vb = (Q0 + 4 * la) * L, (V0 + 4 * la) * L, (Q0 + 4 * lb) * L, (V0 + 4 * lb) * L
        xa, xb = (P_HIPX + la) * L, (P_HIPX + lb) * L
        for b in range(n):
            fx, fy = link_force(x[qa + b], x[qa + L + b], x[va + b], x[va + L + b], x[qb + b],
                                x[qb + L + b], x[vb + b], x[vb + L + b], pt[xa + b], pt[xb + b],
                                pt[P_KBX * L + b], pt[P_KBY * L + b], pt[P_BBX * L + b],
                                pt[P_BBY * L + b])
            tr[2 * k * L + b] = fx
            tr[(2 * k + 1) * L + b] = fy
    for r in range(2 * N_LEGS):
        for b in range(n):
            fh[r * L + b] = 0.0
    for k in range(LINK_HIPS.shape[0]):  # body.body_forces' sums, in its order
        for j in range(2):  # one row of fh and one of tr a loop: LLVM vectorises it
            ra, rf = (2 * LINK_HIPS[k, 0] + j) * L, (2 * k + j) * L
            rb = (2 * LINK_HIPS[k, 1] + j) * L
            for b in range(n):
                fh[ra + b] += tr[rf + b]
            for b in range(n):
                fh[rb + b] -= tr[rf + b]
    for i in range(N_LEGS):
        q, v, w = (Q0 + 4 * i) * L, (V0 + 4 * i) * L, i * W_SIZE * L
        oc, ox = (C0 + i) * L, (X0 + i) * L
        for b in range(n):
            th1 = x[q + 2 * L + b]
            c1, s1 = cos_sin(th1)
            c12, s12 = cos_sin(th1 + x[q + 3 * L + b])
            w1, w2 = x[v + 2 * L + b], x[v + 3 * L + b]
            l1, l2 = pt[P_L1 * L + b], pt[P_L2 * L + b]
            dx, dy = foot_offset_cs(c1, s1, c12, s12, l1, l2)
            xf, yf = x[q + b] + dx, x[q + L + b] + dy
            c, xt = update_contact(xf, yf, x[oc + b], x[ox + b])
            tr[b] = c  # into X after the loop: stores to X here would stop LLVM
            tr[L + b] = xt  # from vectorising (it cannot tell X's rows apart)
            dvx, dvy = foot_velocity_cs(c1, s1, c12, s12, w1, w2, l1, l2)
            vx, vy = x[v + b] + dvx, x[v + L + b] + dvy
            on = c != 0.0  # in flight: no ground force, the plain solve (engine.prepare)
            bx = pt[P_BGX * L + b] if on else 0.0
            by = pt[P_BGY * L + b] if on else 0.0
            fx, fy = spring_damper(xf, yf, vx, vy, xt, pt[P_KGX * L + b], pt[P_KGY * L + b],
                                   bx, by)
            fx = fx if on else 0.0
            fy = fy if on else 0.0
            h = pt[P_DT * L + b] if on and pt[P_IMPL * L + b] != 0.0 else 0.0
            factor, bias, jac = leg_system_cs(c1, s1, c12, s12, w1, w2, l1, l2,
                                              pt[P_MH * L + b], pt[P_MK * L + b],
                                              pt[P_MF * L + b], pt[P_G * L + b], bx, by, h)
            d0, d1, d2, d3, l10, l20, l30, l21, l31, l32 = factor
            f = w + W_FACTOR * L + b
            wk[f], wk[f + L], wk[f + 2 * L], wk[f + 3 * L] = d0, d1, d2, d3
            wk[f + 4 * L], wk[f + 5 * L], wk[f + 6 * L] = l10, l20, l30
            wk[f + 7 * L], wk[f + 8 * L], wk[f + 9 * L] = l21, l31, l32
            f = w + W_BIAS * L + b
            wk[f], wk[f + L], wk[f + 2 * L], wk[f + 3 * L] = bias
            f = w + W_JAC * L + b
            wk[f], wk[f + L], wk[f + 2 * L], wk[f + 3 * L] = jac
            f = w + W_FG * L + b
            wk[f], wk[f + L] = fx, fy
            f = w + W_CS * L + b
            wk[f], wk[f + L], wk[f + 2 * L], wk[f + 3 * L] = c1, s1, c12, s12
            f = w + W_W * L + b
            wk[f], wk[f + L] = w1, w2
        for b in range(n):
            x[oc + b] = tr[b]
            x[ox + b] = tr[L + b]


@njit(cache=True, error_model="numpy")
def block_solve(X, TQ, PT, n, FH, WK, FF, QDD, FLAG):  # type: ignore[no-untyped-def]
    """engine.solve for columns 0..n-1: F_RF into FF, ddq into QDD under torques TQ."""
    x, tq, pt, fh, wk = _flat(X), _flat(TQ), _flat(PT), _flat(FH), _flat(WK)
    ff, qdd = _flat(FF), _flat(QDD)
    L = LANES
    for i in range(N_LEGS):
        w, oc, t, a = i * W_SIZE * L, (C0 + i) * L, 2 * i * L, 4 * i * L
        any_limited = False
        for b in range(n):
            f = w + W_FACTOR * L + b
            factor = (wk[f], wk[f + L], wk[f + 2 * L], wk[f + 3 * L], wk[f + 4 * L],
                      wk[f + 5 * L], wk[f + 6 * L], wk[f + 7 * L], wk[f + 8 * L], wk[f + 9 * L])
            f = w + W_BIAS * L + b
            bias = (wk[f], wk[f + L], wk[f + 2 * L], wk[f + 3 * L])
            f = w + W_JAC * L + b
            af, bf, ja2, jb2 = wk[f], wk[f + L], wk[f + 2 * L], wk[f + 3 * L]
            fx0, fy0 = wk[w + W_FG * L + b], wk[w + (W_FG + 1) * L + b]
            a0, a1, a2, a3 = leg_solve(factor, bias, (af, bf, ja2, jb2), tq[t + b],
                                       tq[t + L + b], fh[t + b], fh[t + L + b], fx0, fy0)
            # engine.leg_contact_solve: ground damping at the end-of-step velocity, limits
            h = pt[P_DT * L + b] if pt[P_IMPL * L + b] != 0.0 else 0.0
            fx, fy = fx0, fy0
            if h > 0.0:
                fx = fx0 - pt[P_BGX * L + b] * (h * (a0 + af * a2 + ja2 * a3))
                fy = fy0 - pt[P_BGY * L + b] * (h * (a1 + bf * a2 + jb2 * a3))
            lx, ly = limit_force(fx, fy, pt[P_MU * L + b])
            contact = x[oc + b] != 0.0
            limited = contact and (lx != fx or ly != fy)
            if not contact:
                lx, ly = 0.0, 0.0
            ff[t + b] = lx
            ff[t + L + b] = ly
            qdd[a + b] = a0
            qdd[a + L + b] = a1
            qdd[a + 2 * L + b] = a2
            qdd[a + 3 * L + b] = a3
            FLAG[b] = 1.0 if limited else 0.0
            any_limited |= limited
        if any_limited:
            for b in range(n):
                if FLAG[b] != 0.0:
                    f = w + W_CS * L + b
                    r = leg_accel_cs(wk[f], wk[f + L], wk[f + 2 * L], wk[f + 3 * L],
                                     wk[w + W_W * L + b], wk[w + (W_W + 1) * L + b],
                                     pt[P_L1 * L + b], pt[P_L2 * L + b], pt[P_MH * L + b],
                                     pt[P_MK * L + b], pt[P_MF * L + b], pt[P_G * L + b],
                                     tq[t + b], tq[t + L + b], fh[t + b], fh[t + L + b],
                                     ff[t + b], ff[t + L + b], 0.0, 0.0, 0.0)
                    for j in range(4):
                        qdd[a + j * L + b] = r[j]


@njit(cache=True)
def block_integrate(X, PT, n, QDD):  # type: ignore[no-untyped-def]
    """engine.advance_prepared's update: dq += dt ddq, then q += dt dq (columns 0..n-1)."""
    x, pt, qdd = _flat(X), _flat(PT), _flat(QDD)
    L = LANES
    for r in range(4 * N_LEGS):
        for b in range(n):
            dt = pt[P_DT * L + b]
            vel = x[(V0 + r) * L + b] + dt * qdd[r * L + b]
            x[(V0 + r) * L + b] = vel
            x[(Q0 + r) * L + b] += dt * vel


@njit(cache=True)
def block_sample(X, TQ, PT, b, FH, WK, FF, QDD, obs):  # type: ignore[no-untyped-def]
    """engine.observe_prepared's sample of column b (after block_prepare and block_solve
    with the held torque) into ``obs`` (9, 6, 2)."""
    for i in range(N_LEGS):
        q, v = Q0 + 4 * i, V0 + 4 * i
        sample = leg_sample(X[q, b], X[q + 1, b], X[q + 2, b], X[q + 3, b], X[v, b],
                            X[v + 1, b], X[v + 2, b], X[v + 3, b], WK[i, W_CS, b],
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


__all__ = ["LANES", "block_integrate", "block_prepare", "block_sample", "block_scratch",
           "block_solve",
           "swap_columns"]
