"""Confidence intervals of a mean and of a paired difference (Student t), without SciPy.

A Monte Carlo index is a sample mean over n seeds; its two-sided interval at level 1 - a is
mean ± t_{1-a/2, n-1} s / sqrt(n), s the sample standard deviation. With common random
numbers, controller B minus controller A is judged on the per-seed differences
d_k = B_k - A_k (a paired t interval), whose spread is far smaller than either index's when
the ground sequence drives most of the variation. The t interval assumes the (differences
of the) seed results are roughly normal; with tens of seeds it is robust to moderate skew.

The Student t quantile comes from the regularized incomplete beta function (continued
fraction, Numerical Recipes 6.4) and bisection; it matches tables to 1e-10.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np


def _betacf(a: float, b: float, x: float) -> float:
    """Continued fraction of the incomplete beta function (modified Lentz)."""
    tiny, eps = 1e-300, 1e-15
    qab, qap, qam = a + b, a + 1.0, a - 1.0
    c, d = 1.0, 1.0 - qab * x / qap
    d = 1.0 / (d if abs(d) > tiny else tiny)
    h = d
    for m in range(1, 1000):
        m2 = 2 * m
        aa = m * (b - m) * x / ((qam + m2) * (a + m2))
        d = 1.0 + aa * d
        d = 1.0 / (d if abs(d) > tiny else tiny)
        c = 1.0 + aa / c
        c = c if abs(c) > tiny else tiny
        h *= d * c
        aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2))
        d = 1.0 + aa * d
        d = 1.0 / (d if abs(d) > tiny else tiny)
        c = 1.0 + aa / c
        c = c if abs(c) > tiny else tiny
        delta = d * c
        h *= delta
        if abs(delta - 1.0) < eps:
            break
    return h


def betainc(a: float, b: float, x: float) -> float:
    """Regularized incomplete beta function I_x(a, b), a, b > 0, x in [0, 1]."""
    if not 0.0 <= x <= 1.0:
        raise ValueError(f"betainc: x = {x!r} is not in [0, 1]")
    if x in (0.0, 1.0):
        return x
    lbt = (math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b) + a * math.log(x)
           + b * math.log1p(-x))
    if x < (a + 1.0) / (a + b + 2.0):
        return math.exp(lbt) * _betacf(a, b, x) / a
    return 1.0 - math.exp(lbt) * _betacf(b, a, 1.0 - x) / b


def t_cdf(t: float, df: float) -> float:
    """P(T <= t) for Student's t with ``df`` > 0 degrees of freedom."""
    if df <= 0:
        raise ValueError(f"degrees of freedom must be > 0, got {df!r}")
    tail = 0.5 * betainc(0.5 * df, 0.5, df / (df + t * t))
    return 1.0 - tail if t > 0 else tail


def t_quantile(q: float, df: float) -> float:
    """The ``q`` quantile (0 < q < 1) of Student's t with ``df`` degrees of freedom."""
    if not 0.0 < q < 1.0:
        raise ValueError(f"quantile level must be in (0, 1), got {q!r}")
    if q < 0.5:
        return -t_quantile(1.0 - q, df)
    lo, hi = 0.0, 1.0
    while t_cdf(hi, df) < q:
        hi *= 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if t_cdf(mid, df) < q:
            lo = mid
        else:
            hi = mid
        if hi - lo <= 1e-13 * max(1.0, hi):
            break
    return 0.5 * (lo + hi)


@dataclass(frozen=True)
class Interval:
    """A sample mean with its two-sided confidence interval [low, high] at ``level``,
    from ``n`` finite samples (Student t with n - 1 degrees of freedom)."""

    mean: float
    low: float
    high: float
    n: int
    level: float

    @property
    def half_width(self) -> float:
        """(high - low) / 2, in the samples' unit."""
        return 0.5 * (self.high - self.low)

    def contains(self, value: float) -> bool:
        """True if ``value`` lies in [low, high]."""
        return self.low <= value <= self.high

    @property
    def excludes_zero(self) -> bool:
        """True if the interval lies wholly above or below 0 (a difference is resolved)."""
        return self.low > 0.0 or self.high < 0.0

    def as_dict(self) -> dict[str, float]:
        """JSON-ready (NaN for a missing bound)."""
        return {"mean": self.mean, "low": self.low, "high": self.high, "n": self.n,
                "level": self.level}


def mean_interval(samples: Sequence[float] | np.ndarray, level: float = 0.95) -> Interval:
    """Mean of the finite ``samples`` with its Student t interval at ``level``; NaN samples
    (diverged runs) are left out and not counted in n. Fewer than two: bounds are NaN."""
    if not 0.0 < level < 1.0:
        raise ValueError(f"confidence level must be in (0, 1), got {level!r}")
    x = np.asarray(samples, dtype=float)
    x = x[np.isfinite(x)]
    n = int(x.size)
    if n == 0:
        return Interval(math.nan, math.nan, math.nan, 0, level)
    mean = float(np.mean(x))
    if n < 2:
        return Interval(mean, math.nan, math.nan, n, level)
    half = t_quantile(0.5 + 0.5 * level, n - 1) * float(np.std(x, ddof=1)) / math.sqrt(n)
    return Interval(mean, mean - half, mean + half, n, level)


def paired_interval(a: Sequence[float] | np.ndarray, b: Sequence[float] | np.ndarray,
                    level: float = 0.95) -> Interval:
    """Mean of b_k - a_k over the pairs where both are finite, with its paired Student t
    interval at ``level``."""
    xa, xb = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if xa.shape != xb.shape:
        raise ValueError(f"paired samples need equal lengths, got {xa.size} and {xb.size}")
    return mean_interval(xb - xa, level)


__all__ = ["Interval", "betainc", "mean_interval", "paired_interval", "t_cdf", "t_quantile"]
