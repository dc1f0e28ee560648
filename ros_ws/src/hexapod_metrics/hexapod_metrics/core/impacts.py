"""Torque at foot impacts: a C4 number with a continuous-time limit.

The paper says PD-P&F, with ideal actuators on hard ground, hits the feet with torque
impulses. The largest tick-to-tick torque change does not measure that in a way a step size
can settle: a difference of samples of a signal with fast transients grows as the
transients are resolved (23-51x PD-P's across dt, dt/2, dt/4 in the committed report).
Here, per touchdown:

* **peak** |T_m| over both joints of the landing leg within a fixed window W (default
  20 ms) after the touchdown (N m): an impact that shows in the torque raises it;
* **impulse** of the torque above its low-pass: the integral over the same window of
  |T_m - LP(T_m)| summed over both joints (N m s), LP a first-order low-pass of time
  constant W run causally from t = 0: the fast part of the torque, weighted by duration.

Both are averaged over the touchdowns in the evaluation window. A touchdown is the gait's,
not every contact: for each stance phase of the reference (its first support tick k_s) the
first tick from k_s - t_T/2 on at which the foot is below the ground (y_F < 0, the
engine's contact rule). A foot that bounces therefore counts once per step, and the window
is a fixed time span, so both numbers are averages of samples at fixed instants of a run
that converges in dt: they converge with it (tests/test_impacts.py: dt, dt/2, dt/4 within
1 %).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hexapod_common.core.layout import O_FP, O_TQ

#: Default window after a touchdown (s).
WINDOW = 0.02


@dataclass(frozen=True)
class ImpactTorque:
    """Mean over ``count`` touchdowns of the peak |T_m| (N m) and of the impulse of T_m
    above its low-pass (N m s), within ``window`` s after each; NaN if no touchdown."""

    peak: float
    impulse: float
    count: int
    window: float


def touchdown_ticks(foot_y: np.ndarray, support: np.ndarray, transfer_ticks: int,
                    k_a: int, k_b: int) -> list[tuple[int, int]]:
    """(leg, tick) of every gait touchdown whose stance starts in ticks [k_a, k_b).

    ``foot_y`` (N, 6) foot heights (m), ``support`` (N, 6) the reference's stance flags,
    ``transfer_ticks`` the transfer phase in ticks (the search starts half of it before the
    scheduled touchdown)."""
    out = []
    n = foot_y.shape[0]
    half = max(1, transfer_ticks // 2)
    for leg in range(foot_y.shape[1]):
        s = support[:, leg]
        starts = np.flatnonzero(s[1:] & ~s[:-1]) + 1
        for ks in starts:
            if not k_a <= ks < k_b:
                continue
            below = np.flatnonzero(foot_y[max(0, ks - half):n, leg] < 0.0)
            if below.size:
                out.append((leg, int(max(0, ks - half) + below[0])))
    return out


def low_pass(x: np.ndarray, dt: float, tau: float) -> np.ndarray:
    """First-order low-pass (time constant ``tau`` s) of samples ``x`` (N, ...) at step
    ``dt`` s, exact for a signal held between samples, starting from x[0]."""
    a = float(np.exp(-dt / tau))
    y = np.empty_like(x)
    y[0] = x[0]
    for k in range(1, x.shape[0]):
        y[k] = a * y[k - 1] + (1.0 - a) * x[k]
    return y


def impact_torque(obs: np.ndarray, support: np.ndarray, dt: float, transfer_time: float,
                  k_a: int, k_b: int, window: float = WINDOW) -> ImpactTorque:
    """The impact numbers of a run sampled at control ticks of ``dt`` s.

    ``obs`` (N, 9, 6, 2) the run's samples from t = 0 (layout.OBS_FIELDS), ``support``
    (N, 6) the reference's stance flags at the same ticks, ``transfer_time`` t_T (s);
    touchdowns whose stance starts in ticks [k_a, k_b) count (the evaluation window)."""
    if not window > 0:
        raise ValueError(f"impact window = {window!r} s: must be > 0")
    tq = obs[:, O_TQ]                       # (N, 6, 2) torque acting at each tick
    width = int(round(window / dt))
    events = touchdown_ticks(obs[:, O_FP, :, 1], support, int(round(transfer_time / dt)),
                             k_a, k_b)
    events = [(leg, k) for leg, k in events if k + width < tq.shape[0]]
    if not events:
        return ImpactTorque(float("nan"), float("nan"), 0, window)
    fast = np.abs(tq - low_pass(tq, dt, window))
    peaks = [float(np.max(np.abs(tq[k:k + width + 1, leg]))) for leg, k in events]
    # samples 1..width after the touchdown tick, each the torque over the interval before it
    impulses = [float(np.sum(fast[k + 1:k + width + 1, leg]) * dt) for leg, k in events]
    return ImpactTorque(float(np.mean(peaks)), float(np.mean(impulses)), len(events), window)


__all__ = ["ImpactTorque", "WINDOW", "impact_torque", "low_pass", "touchdown_ticks"]
