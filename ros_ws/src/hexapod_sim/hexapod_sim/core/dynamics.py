"""Per-leg rigid-body dynamics with three point masses (paper eq. 5, model.md "Dynamics").

Leg coordinates q = [x_H, y_H, theta1, theta2]; point masses m_H at the hip, m_K at the knee,
m_F at the foot (model.md "Masses" [resolution]). With J_k = dp_k/dq:

    H(q)     = sum_k m_k J_k^T J_k                      (4x4, kg / kg m / kg m^2)
    c(q, dq) = sum_k m_k J_k^T (dJ_k dq)
    g(q)     = -sum_k m_k J_k^T [0, -g]
    H ddq + c + g = tau + J_H^T F_RH + J_F^T F_RF,   tau = [0, 0, T_m1, T_m2]

Everything is written in scalars so that numba compiles it to allocation-free code.
"""
from __future__ import annotations

import numpy as np
from hexapod_common.core.jit import njit


@njit(cache=True)
def leg_terms(th1, th2, w1, w2, l1, l2, mh, mk, mf, grav):  # type: ignore[no-untyped-def]
    """Mass matrix and bias of one leg at joint angles (th1, th2): see :func:`leg_terms_cs`."""
    return leg_terms_cs(np.cos(th1), np.sin(th1), np.cos(th1 + th2), np.sin(th1 + th2),
                        w1, w2, l1, l2, mh, mk, mf, grav)


@njit(cache=True, forceinline=True, error_model="numpy")
def leg_terms_cs(c1, s1, c12, s12, w1, w2, l1, l2, mh, mk, mf,  # type: ignore[no-untyped-def]
                 grav):
    """Mass matrix and bias of one leg, given cos/sin of theta1 and of theta1 + theta2.

    Returns (m, H02, H03, H12, H13, H22, H23, H33, b0, b1, b2, b3) where H00 = H11 = m
    (the leg's total mass), H01 = 0, and b = c + g (N, N, N m, N m).
    """
    a1, b1 = l1 * c1, l1 * s1          # d p_K / d theta1
    a2, b2 = l2 * c12, l2 * s12        # d p_F / d theta2
    af, bf = a1 + a2, b1 + b2          # d p_F / d theta1
    m = mh + mk + mf
    h02 = mk * a1 + mf * af
    h03 = mf * a2
    h12 = mk * b1 + mf * bf
    h13 = mf * b2
    h22 = mk * l1 * l1 + mf * (af * af + bf * bf)
    h23 = mf * (a2 * af + b2 * bf)
    h33 = mf * l2 * l2
    # dJ dq of knee and foot (centripetal accelerations).
    w12 = w1 + w2
    kx, ky = -b1 * w1 * w1, a1 * w1 * w1
    fx, fy = kx - b2 * w12 * w12, ky + a2 * w12 * w12
    bias0 = mk * kx + mf * fx
    bias1 = mk * ky + mf * fy + m * grav
    bias2 = mk * (a1 * kx + b1 * ky) + mf * (af * fx + bf * fy) + grav * h12
    bias3 = mf * (a2 * fx + b2 * fy) + grav * h13
    return m, h02, h03, h12, h13, h22, h23, h33, bias0, bias1, bias2, bias3


@njit(cache=True, forceinline=True, error_model="numpy")
def factor_spd4(a00, a01, a02, a03, a11, a12, a13, a22, a23, a33):  # type: ignore[no-untyped-def]
    """LDL^T factor of a symmetric positive definite 4x4 A (upper triangle given).

    Returns (d0, d1, d2, d3, l10, l20, l30, l21, l31, l32) for :func:`subst_spd4`.
    """
    d0 = a00
    l10 = a01 / d0
    l20 = a02 / d0
    l30 = a03 / d0
    d1 = a11 - l10 * l10 * d0
    l21 = (a12 - l20 * l10 * d0) / d1
    l31 = (a13 - l30 * l10 * d0) / d1
    d2 = a22 - l20 * l20 * d0 - l21 * l21 * d1
    l32 = (a23 - l30 * l20 * d0 - l31 * l21 * d1) / d2
    d3 = a33 - l30 * l30 * d0 - l31 * l31 * d1 - l32 * l32 * d2
    return d0, d1, d2, d3, l10, l20, l30, l21, l31, l32


@njit(cache=True, forceinline=True, error_model="numpy")
def subst_spd4(f, r0, r1, r2, r3):  # type: ignore[no-untyped-def]
    """Solve A x = r given the factor ``f`` of A from :func:`factor_spd4`."""
    d0, d1, d2, d3, l10, l20, l30, l21, l31, l32 = f
    y0 = r0
    y1 = r1 - l10 * y0
    y2 = r2 - l20 * y0 - l21 * y1
    y3 = r3 - l30 * y0 - l31 * y1 - l32 * y2
    x3 = y3 / d3
    x2 = y2 / d2 - l32 * x3
    x1 = y1 / d1 - l21 * x2 - l31 * x3
    x0 = y0 / d0 - l10 * x1 - l20 * x2 - l30 * x3
    return x0, x1, x2, x3


@njit(cache=True, error_model="numpy")
def solve_spd4(a00, a01, a02, a03, a11, a12, a13, a22, a23, a33,  # type: ignore[no-untyped-def]
               r0, r1, r2, r3):
    """Solve A x = r for a symmetric positive definite 4x4 A (upper triangle given), by LDL^T."""
    return subst_spd4(factor_spd4(a00, a01, a02, a03, a11, a12, a13, a22, a23, a33),
                      r0, r1, r2, r3)


@njit(cache=True)
def leg_accel(th1, th2, w1, w2, l1, l2, mh, mk, mf, grav, tm1, tm2,  # type: ignore[no-untyped-def]
              fhx, fhy, ffx, ffy, bx, by, h):
    """ddq of one leg at joint angles (th1, th2): see :func:`leg_accel_cs`."""
    return leg_accel_cs(np.cos(th1), np.sin(th1), np.cos(th1 + th2), np.sin(th1 + th2),
                        w1, w2, l1, l2, mh, mk, mf, grav, tm1, tm2, fhx, fhy, ffx, ffy, bx, by, h)


@njit(cache=True, forceinline=True, error_model="numpy")
def leg_system_cs(c1, s1, c12, s12, w1, w2, l1, l2, mh, mk, mf, grav,  # type: ignore[no-untyped-def]
                  bx, by, h):
    """The state part of :func:`leg_accel_cs`: everything that does not depend on forces.

    Returns (factor, bias, jac): the LDL^T factor (see :func:`factor_spd4`) of
    H + h J_F^T diag(bx, by) J_F, the bias b = c + g (b0, b1, b2, b3) (N, N, N m, N m) and
    the foot Jacobian's angle columns (af, bf, a2, b2) (m) with J_F = [[1, 0, af, a2],
    [0, 1, bf, b2]]. :func:`leg_solve` turns them and the forces into ddq.
    """
    m, h02, h03, h12, h13, h22, h23, h33, bb0, bb1, bb2, bb3 = leg_terms_cs(
        c1, s1, c12, s12, w1, w2, l1, l2, mh, mk, mf, grav)
    a2, b2 = l2 * c12, l2 * s12
    af, bf = l1 * c1 + a2, l1 * s1 + b2
    # J_F = [[1, 0, af, a2], [0, 1, bf, b2]]; D = h J_F^T diag(bx, by) J_F
    hx, hy = h * bx, h * by
    factor = factor_spd4(
        m + hx, 0.0, h02 + hx * af, h03 + hx * a2,
        m + hy, h12 + hy * bf, h13 + hy * b2,
        h22 + hx * af * af + hy * bf * bf, h23 + hx * af * a2 + hy * bf * b2,
        h33 + hx * a2 * a2 + hy * b2 * b2)
    return factor, (bb0, bb1, bb2, bb3), (af, bf, a2, b2)


@njit(cache=True, forceinline=True, error_model="numpy")
def leg_solve(factor, bias, jac, tm1, tm2, fhx, fhy, ffx, ffy):  # type: ignore[no-untyped-def]
    """The force part of :func:`leg_accel_cs`: ddq from the state part of
    :func:`leg_system_cs`, joint torques tm1, tm2 (N m), the body force (fhx, fhy) on the hip
    and the ground force (ffx, ffy) on the foot (N). Returns (ddx_H, ddy_H, ddth1, ddth2)."""
    bb0, bb1, bb2, bb3 = bias
    af, bf, a2, b2 = jac
    return subst_spd4(factor, fhx + ffx - bb0, fhy + ffy - bb1,
                      tm1 + af * ffx + bf * ffy - bb2, tm2 + a2 * ffx + b2 * ffy - bb3)


@njit(cache=True, forceinline=True, error_model="numpy")
def leg_accel_cs(c1, s1, c12, s12, w1, w2, l1, l2, mh, mk, mf, grav,  # type: ignore[no-untyped-def]
                 tm1, tm2, fhx, fhy, ffx, ffy, bx, by, h):
    """ddq of one leg (cos/sin of theta1 and theta1 + theta2 given) from
    H ddq + c + g = tau + J_H^T F_RH + J_F^T F_RF (paper eq. 5).

    tm1, tm2: joint torques (N m); (fhx, fhy): body force on the hip (N); (ffx, ffy): ground
    force on the foot at the current velocity (N). (bx, by) (N s/m) and h (s): ground damping
    taken linearly implicit over a step h, i.e. F_RF = F - h B J_F ddq, which gives
    (H + h J_F^T B J_F) ddq = rhs. h = 0 is the plain explicit solve.
    Returns (ddx_H, ddy_H, ddtheta1, ddtheta2). It is :func:`leg_system_cs` followed by
    :func:`leg_solve`, which the engine calls separately to share the first between the
    observation and the next step.
    """
    factor, bias, jac = leg_system_cs(c1, s1, c12, s12, w1, w2, l1, l2, mh, mk, mf, grav,
                                      bx, by, h)
    return leg_solve(factor, bias, jac, tm1, tm2, fhx, fhy, ffx, ffy)


def mass_matrix(q: np.ndarray, l1: float, l2: float, mh: float, mk: float,
                mf: float) -> np.ndarray:
    """Full 4x4 H(q) of one leg (for tests and comparisons), q = [x_H, y_H, th1, th2]."""
    h00, h02, h03, h12, h13, h22, h23, h33, *_ = leg_terms(
        q[2], q[3], 0.0, 0.0, l1, l2, mh, mk, mf, 0.0)
    return np.array([[h00, 0.0, h02, h03], [0.0, h00, h12, h13],
                     [h02, h12, h22, h23], [h03, h13, h23, h33]])


def bias_forces(q: np.ndarray, dq: np.ndarray, l1: float, l2: float, mh: float, mk: float,
                mf: float, grav: float) -> np.ndarray:
    """c(q, dq) + g(q) of one leg (for tests and comparisons)."""
    return np.array(leg_terms(q[2], q[3], dq[2], dq[3], l1, l2, mh, mk, mf, grav)[8:])


__all__ = ["bias_forces", "factor_spd4", "leg_accel", "leg_accel_cs", "leg_solve", "leg_system_cs",
           "leg_terms", "leg_terms_cs", "mass_matrix", "solve_spd4", "subst_spd4"]
