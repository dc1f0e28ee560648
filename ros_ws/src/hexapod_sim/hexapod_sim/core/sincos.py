"""cos and sin of one angle at once, in plain arithmetic: the engines' trigonometry.

Why not libm: the batched engine (batch_physics.py) steps many cases in one loop, which
LLVM turns into vector instructions (8 doubles an AVX-512 instruction) only if every
operation in the loop has a vector form. libm's cos and sin are scalar calls. This
function is additions, multiplications, one floor and selects, so a loop that calls it
vectorises; and since numba compiles without fast-math (no FMA contraction, no
reassociation), a vector lane computes the same IEEE operations in the same order as a
scalar call: the single run (engine.py) and the batch get the same bits.

Method (the fdlibm/FreeBSD msun algorithm, without its branches):

1. Reduction: n = the integer nearest x 2/pi (x 2/pi + 1.5 2^52 - 1.5 2^52), and
   x - n pi/2 = y0 + y1 (a double and its tail), pi/2 split into P1 + P2 + P2T (P1, P2 33
   bits each, P2T the rest rounded): r1 = x - n P1 and p2 = n P2 are exact for |n| < 2^20
   (products of at most 53 bits; x and n P1 within a factor 2 of each other, Sterbenz),
   r1 - p2 = s + e exactly (TwoSum), t = e - n P2T, and s + t = y0 + y1 exactly (TwoSum).
2. Kernels on [-pi/4, pi/4] (FreeBSD msun k_sin.c, k_cos.c: polynomials of degree 13 and
   14 whose approximation errors are below 2^-58, evaluated with the tail y1).
3. Quadrant n mod 4 chooses and signs: (cos, sin) = (c, s), (-s, c), (-c, -s), (s, -c).

Precision. The reduction's absolute error is that of n P2T, of t and of pi/2 - P1 - P2 -
P2T: below |n| 2^-120.7. The closest a double x = n pi/2 + y with 1 <= n <= 6400
(|x| <= 1e4 rad) comes to a multiple of pi/2 is |y| = 2^-60.49 (x = 45.55, n = 29; exact
integer arithmetic over every n, see tests/test_sincos.py), so there the reduced argument
is off by at most 2^-55.4 of itself (0.2 ulp) and by far less elsewhere; the kernels add
under 1 ulp. tests/test_sincos.py measures the result against extended precision at a
million random angles in [-1e4, 1e4] and at the doubles nearest every multiple of pi/2 up
to 1e4 rad: within 1 ulp (measured: 0.78 ulp at most, libm's cos and sin 0.52). Up to
|x| = 2^20 pi/2 the absolute error of the reduced argument stays below 2^-100 rad (so cos
and sin within 1 ulp + 2^-100); beyond, n P1 is no longer exact and the error grows with
|x| (no state of the engine gets there: engine.MAX_COORD is 1e4 rad). Non-finite x gives
NaN.

Coefficients and kernels from FreeBSD lib/msun/src/k_sin.c, k_cos.c, e_rem_pio2.c:
  Copyright (C) 1993 by Sun Microsystems, Inc. All rights reserved.
  Developed at SunSoft, a Sun Microsystems, Inc. business.
  Permission to use, copy, modify, and distribute this software is freely granted,
  provided that this notice is preserved.
"""
from __future__ import annotations

import numpy as np
from hexapod_common.core.jit import njit

INV_PIO2 = 6.36619772367581382433e-01  # 2/pi, 53 bits
PIO2_1 = 1.57079632673412561417e+00    # first 33 bits of pi/2
PIO2_2 = 6.07710050630396597660e-11    # second 33 bits of pi/2
PIO2_2T = 2.02226624879595063154e-21   # pi/2 - (PIO2_1 + PIO2_2), rounded
ROUNDER = 6755399441055744.0           # 1.5 * 2^52: x + ROUNDER - ROUNDER rounds x

S1 = -1.66666666666666324348e-01
S2 = 8.33333333332248946124e-03
S3 = -1.98412698298579493134e-04
S4 = 2.75573137070700676789e-06
S5 = -2.50507602534068634195e-08
S6 = 1.58969099521155010221e-10

C1 = 4.16666666666666019037e-02
C2 = -1.38888888888741095749e-03
C3 = 2.48015872894767294178e-05
C4 = -2.75573143513906633035e-07
C5 = 2.08757232129817482790e-09
C6 = -1.13596475577881948265e-11


@njit(cache=True, forceinline=True)
def kernel_sin(x, y):  # type: ignore[no-untyped-def]
    """sin(x + y) for |x| <= ~pi/4 and y the tail of x (|y| < ulp(x))."""
    z = x * x
    w = z * z
    r = S2 + z * (S3 + z * S4) + z * w * (S5 + z * S6)
    v = z * x
    return x - ((z * (0.5 * y - v * r) - y) - v * S1)


@njit(cache=True, forceinline=True)
def kernel_cos(x, y):  # type: ignore[no-untyped-def]
    """cos(x + y) for |x| <= ~pi/4 and y the tail of x (|y| < ulp(x))."""
    z = x * x
    w = z * z
    r = z * (C1 + z * (C2 + z * C3)) + w * w * (C4 + z * (C5 + z * C6))
    hz = 0.5 * z
    u = 1.0 - hz
    return u + (((1.0 - u) - hz) + (z * r - x * y))


@njit(cache=True, forceinline=True)
def cos_sin(x):  # type: ignore[no-untyped-def]
    """(cos x, sin x) of an angle x (rad), within 1 ulp for |x| <= 1e4 (module docstring);
    branch-free, so that loops over many angles vectorise."""
    fn = (x * INV_PIO2 + ROUNDER) - ROUNDER
    r1 = x - fn * PIO2_1
    p2 = fn * PIO2_2
    s = r1 - p2
    bv = s - r1  # TwoSum: s + e = r1 - p2 exactly
    e = (r1 - (s - bv)) - (p2 + bv)
    t = e - fn * PIO2_2T
    y0 = s + t
    bv = y0 - s  # TwoSum: y0 + y1 = s + t exactly
    y1 = (s - (y0 - bv)) + (t - bv)
    sn = kernel_sin(y0, y1)
    cs = kernel_cos(y0, y1)
    q = fn - 4.0 * np.floor(fn * 0.25)  # n mod 4, exactly
    odd = (q == 1.0) | (q == 3.0)
    c = sn if odd else cs
    s_ = cs if odd else sn
    c = -c if (q == 1.0) | (q == 2.0) else c
    s_ = -s_ if q >= 2.0 else s_
    return c, s_


__all__ = ["cos_sin", "kernel_cos", "kernel_sin"]
