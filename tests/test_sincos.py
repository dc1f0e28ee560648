"""The engines' cos/sin (hexapod_sim.core.sincos): within 1 ulp of the exact values, and
the same bits from a scalar call and from a vectorised loop."""
from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest
from numba import njit

from hexapod_sim.core.sincos import cos_sin

#: pi/2 times 2^PREC, from Machin's formula in integers (exact to ~2^-290).
PREC = 300


def _arctan_inv(n: int, prec: int) -> int:
    """arctan(1/n) 2^prec by its series, in integers."""
    s, t, k, sign = 0, (1 << prec) // n, 1, 1
    while t:
        s += sign * (t // k)
        t //= n * n
        k += 2
        sign = -sign
    return s


PIO2 = (4 * _arctan_inv(5, PREC + 20) - _arctan_inv(239, PREC + 20)) >> 19  # (pi/2) 2^PREC


@njit(cache=True)
def _cos_sin_array(x, c, s):  # type: ignore[no-untyped-def]
    for i in range(x.size):
        c[i], s[i] = cos_sin(x[i])


def _ulps(ours: np.ndarray, exact: np.ndarray) -> np.ndarray:
    """|ours - exact| in units of the last place of exact rounded to a double."""
    ulp = np.spacing(np.abs(exact.astype(np.float64)))
    return np.asarray(np.abs(ours.astype(np.longdouble) - exact) / ulp, dtype=np.float64)


def _eval(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    c, s = np.empty_like(x), np.empty_like(x)
    _cos_sin_array(x, c, s)
    return c, s


def test_within_one_ulp_of_extended_precision_at_random_angles() -> None:
    if np.finfo(np.longdouble).nmant < 63:
        pytest.skip("needs x87 extended precision for the reference values")
    rng = np.random.default_rng(7)
    x = np.concatenate([rng.uniform(-1e4, 1e4, 500_000), rng.uniform(-4.0, 4.0, 500_000),
                        np.array([0.0, -0.0, math.pi / 4, 1e-300, 5e-324, 1e4, -1e4])])
    c, s = _eval(x)
    xl = x.astype(np.longdouble)
    ec, es = _ulps(c, np.cos(xl)), _ulps(s, np.sin(xl))
    assert ec.max() < 1.0, x[ec.argmax()]
    assert es.max() < 1.0, x[es.argmax()]


def _exact_near_zero(x: float, k: int) -> tuple[Fraction, int]:
    """y = x - k pi/2 (x >= 0) to 2^-PREC, from exact integers, and k mod 4."""
    num, den = x.as_integer_ratio()  # den is a power of two below 2^PREC here
    return Fraction(num * (1 << PREC) // den - k * PIO2, 1 << PREC), k % 4


def test_within_one_ulp_next_to_every_multiple_of_pi_half_up_to_1e4() -> None:
    """Where cos or sin is near zero the reduction cancels the most: the doubles next to
    k pi/2, k = 1..6400, against their exact value +-y (y = x - k pi/2, |y| < 3e-12, so
    sin y = y to far below an ulp)."""
    worst = 0.0
    for k in range(1, 6401):
        x0 = float(k * PIO2 / 2**PREC)
        for x in (np.nextafter(x0, -np.inf), x0, np.nextafter(x0, np.inf)):
            for sx in (x, -x):
                y, q = _exact_near_zero(abs(sx), k)
                c, s = cos_sin(sx)
                # |x| = k pi/2 + y: the function that vanishes there is +-sin y
                small = c if q % 2 == 1 else s
                want = {0: y, 1: -y, 2: -y, 3: y}[q]  # sin(kpi/2 + y), cos(kpi/2 + y)
                if q % 2 == 0 and sx < 0:
                    want = -want  # sin is odd
                ulp = Fraction(float(np.spacing(abs(float(want)))))
                worst = max(worst, float(abs(Fraction(float(small)) - want) / ulp))
    assert worst < 1.0


def test_no_double_up_to_1e4_is_nearer_a_multiple_of_pi_half_than_the_docstring_says() -> None:
    """The constant of sincos.py's precision argument: |x - k pi/2| >= 2^-60.49 for every
    double x and 1 <= k <= 6400 (reached at k = 29, x = 45.55)."""
    worst, at = 1.0, 0
    for k in range(1, 6401):
        v = k * PIO2
        ulp = 1 << (PREC + v.bit_length() - PREC - 1 - 52)
        r = v % ulp
        d = min(r, ulp - r) / 2.0**PREC
        if d < worst:
            worst, at = d, k
    assert at == 29
    assert math.log2(worst) == pytest.approx(-60.49, abs=0.005)


def test_a_vectorised_loop_and_a_scalar_call_give_the_same_bits() -> None:
    rng = np.random.default_rng(3)
    x = np.concatenate([rng.uniform(-10.0, 10.0, 4099), [np.nan, np.inf, -np.inf]])
    c, s = _eval(x)
    scalar = np.array([cos_sin(float(v)) for v in x])
    np.testing.assert_array_equal(c, scalar[:, 0])
    np.testing.assert_array_equal(s, scalar[:, 1])
    assert np.isnan(c[-3:]).all() and np.isnan(s[-3:]).all()
    assert cos_sin(0.0) == (1.0, 0.0)
