"""The seven performance indices (paper eqs. 8-11), over one evaluation window.

Input: N_S + 1 samples at the control ticks t_a = t_0 < t_1 < ... < t_N = t_b, spaced
Delta t. L is measured between the first and the last sample; the sums and means run over
samples 1..N (each sample carries the torque that acted over the period ending at it, see
hexapod_sim.core.engine), so consecutive windows tile the run without overlap:

    L      = mean_i (x_iH(t_b) - x_iH(t_a))                          distance walked (m)
    E_av   = (1/L) sum_i sum_j sum_k |T_mij dtheta_ij| Delta t       (8)  J/m
    T_L    = (1/L) sqrt(sum_i sum_j sum_k T_mij^2 Delta t)           (9)  N m s^0.5 / m
    F_L    = (1/L) sqrt(sum_i sum_k (f_ix^2 + f_iy^2) Delta t)       (10) N s^0.5 / m
    eps_xH = sum_i sqrt(mean_k (x_iHd - x_iH)^2), eps_yH, eps_xF, eps_yF alike (11a-d) (m)

Beside eq. (11), not one of the paper's indices: lag_xH = mean_i mean_k (x_iHd - x_iH) (m), how
far the hips trail the commanded x = V_F t on average. In a long run eps_xH keeps growing
because the lag grows a little each cycle; the lag and its growth per cycle (the difference
between consecutive cycles) tell that drift apart from the tracking within a cycle.

Drift and tracking (ours; docs/indices.md): with e_i(t) = x_id(t) - x_i(t) the horizontal
error of leg i (hip or foot), eq. (11a, c) per leg splits exactly into its mean over the
window (the offset o_i, which grows by the drift every cycle) and what is left (the
tracking, which does not):

    sqrt(mean_k e_ik^2) = sqrt(o_i^2 + s_i^2),   o_i = mean_k e_ik,   s_i^2 = mean_k (e_ik - o_i)^2
    trk_xH = sum_i s_iH, trk_xF = sum_i s_iF                                   (m)
    drift_xH = mean_i (e_iH(t_b) - e_iH(t_a)) / (t_b - t_a), drift_xF alike    (m/s)

drift_xH T is how far the body falls behind the reference per gait cycle: V_F T - L for the
hips, whose reference is x = V_F t. Both are stationary in a steady gait (cycle 10 and 20
agree; tests/test_drift.py), where eps_xH and eps_xF grow with the run.

[resolution, model.md] eq. (10) sums over j although its integrand has no j: we drop that
sum. The paper's Fig. 9 calls F_L "P_L".
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import Sequence

import numpy as np

from hexapod_common.core.errors import ParameterError
from hexapod_common.core.index_sums import (A_E0, A_E1, A_ENERGY, A_EX, A_FORCE2, A_FY_MIN,
                                            A_HY_MAX, A_HY_MIN, A_LAG, A_SAMPLES, A_SQ,
                                            A_TORQUE2, A_X0, A_X1, accumulate,
                                            new_accumulator)
from hexapod_common.core.layout import O_FP, O_HF, O_HP, O_THV, O_TQ
from hexapod_common.core.params import N_LEGS, HexapodParams

#: Index names in report order, with units.
INDEX_NAMES = ("E_av", "T_L", "F_L", "eps_xH", "eps_yH", "eps_xF", "eps_yF")
#: Ours, beside eq. (11): the drift of the hips and feet behind their reference and the
#: horizontal errors without each leg's mean offset (module doc): window-independent.
DRIFT_NAMES = ("drift_xH", "drift_xF", "trk_xH", "trk_xF")
#: The seven, then the distance walked, the hip lag and the drift indices every result
#: also carries.
REPORTED_NAMES = INDEX_NAMES + ("L", "lag_xH") + DRIFT_NAMES
INDEX_UNITS = {"E_av": "J/m", "T_L": "N m s^0.5/m", "F_L": "N s^0.5/m", "eps_xH": "m",
               "eps_yH": "m", "eps_xF": "m", "eps_yF": "m", "L": "m", "lag_xH": "m",
               "drift_xH": "m/s", "drift_xF": "m/s", "trk_xH": "m", "trk_xF": "m"}


@dataclass(frozen=True)
class Indices:
    """The seven indices of one window, the distance L they are normalised by, the mean
    hip lag lag_xH (m), the drift speeds drift_xH, drift_xF (m/s) and the detrended
    horizontal errors trk_xH, trk_xF (m) (NaN where they were not recorded, e.g. in older
    bags)."""

    E_av: float
    T_L: float
    F_L: float
    eps_xH: float
    eps_yH: float
    eps_xF: float
    eps_yF: float
    L: float
    lag_xH: float = float("nan")
    drift_xH: float = float("nan")
    drift_xF: float = float("nan")
    trk_xH: float = float("nan")
    trk_xF: float = float("nan")

    def as_dict(self) -> dict[str, float]:
        """Name -> value, including L."""
        return asdict(self)


@dataclass(frozen=True)
class WindowSums:
    """The additive parts of the indices over a window: consecutive windows add up.

    energy = sum |T theta_dot| dt; torque2 = sum T^2 dt; force2 = sum |f|^2 dt (all legs and
    joints); sq_err (4, 6) = per-leg sums of squared errors of x_H, y_H, x_F, y_F; samples =
    N_S; distance = L; lag = sum of x_Hd - x_H over samples and legs; x_err (2, 6) = per-leg
    sums of the horizontal errors of x_H, x_F; e_first, e_last (2, 6) = those errors at t_a
    and at t_b; span = t_b - t_a (s); hip_y (lowest, highest) hip height and foot_y_min the
    lowest foot height over the samples (m: hexapod_metrics.core.walking).
    """

    energy: float
    torque2: float
    force2: float
    sq_err: np.ndarray
    samples: int
    distance: float
    lag: float = 0.0
    x_err: np.ndarray | None = None
    e_first: np.ndarray | None = None
    e_last: np.ndarray | None = None
    span: float = float("nan")
    hip_y: tuple[float, float] = (float("nan"), float("nan"))
    foot_y_min: float = float("nan")

    def __add__(self, other: "WindowSums") -> "WindowSums":
        """The sums of this window followed by ``other`` (the next one)."""
        x_err = (None if self.x_err is None or other.x_err is None
                 else self.x_err + other.x_err)
        return WindowSums(self.energy + other.energy, self.torque2 + other.torque2,
                          self.force2 + other.force2, self.sq_err + other.sq_err,
                          self.samples + other.samples, self.distance + other.distance,
                          self.lag + other.lag, x_err, self.e_first, other.e_last,
                          self.span + other.span,
                          (min(self.hip_y[0], other.hip_y[0]),
                           max(self.hip_y[1], other.hip_y[1])),
                          min(self.foot_y_min, other.foot_y_min))

    def x_error_parts(self) -> tuple[np.ndarray, np.ndarray]:
        """(offset, tracking) (2, 6) m: per leg (rows x_H, x_F) the mean horizontal error
        o_i and the root mean square s_i of what is left; sqrt(o^2 + s^2) is eq. (11a, c)'s
        term of that leg (module doc)."""
        if self.x_err is None:
            nan = np.full((2, self.sq_err.shape[1]), np.nan)
            return nan, nan
        offset = self.x_err / self.samples
        ms = self.sq_err[[0, 2]] / self.samples
        return offset, np.sqrt(np.maximum(ms - offset * offset, 0.0))

    def indices(self) -> Indices:
        """Eqs. (8)-(11) from the sums."""
        dist = self.distance
        rms = np.sqrt(self.sq_err / self.samples).sum(axis=1)
        _, trk = self.x_error_parts()
        if self.e_first is None or self.e_last is None:
            drift = np.full(2, np.nan)
        else:
            drift = (self.e_last - self.e_first).mean(axis=1) / self.span
        return Indices(self.energy / dist, float(np.sqrt(self.torque2)) / dist,
                       float(np.sqrt(self.force2)) / dist, float(rms[0]), float(rms[1]),
                       float(rms[2]), float(rms[3]), dist,
                       self.lag / (self.samples * self.sq_err.shape[1]),
                       float(drift[0]), float(drift[1]), float(trk[0].sum()),
                       float(trk[1].sum()))


def window_sums(torque: np.ndarray, joint_vel: np.ndarray, hip_force: np.ndarray,
                hip_pos: np.ndarray, hip_ref: np.ndarray, foot_pos: np.ndarray,
                foot_ref: np.ndarray, dt: float) -> WindowSums:
    """:class:`WindowSums` of (N+1, 6, 2) sample arrays (row 0 only supplies x_iH(t_a)),
    through the compiled accumulator the batched engine scores with
    (hexapod_common.core.index_sums)."""
    if hip_pos.shape[0] < 2:
        raise ValueError("an evaluation window needs at least two samples")
    acc = new_accumulator()
    accumulate(acc, *(np.asarray(a, dtype=np.float64) for a in
                      (torque, joint_vel, hip_force, hip_pos, hip_ref, foot_pos, foot_ref)))
    return sums_from_accumulator(acc, dt)


def sums_from_accumulator(acc: np.ndarray, dt: float) -> WindowSums:
    """:class:`WindowSums` of an accumulator (hexapod_common.core.index_sums) of samples
    spaced ``dt`` (s)."""
    return WindowSums(float(acc[A_ENERGY]) * dt, float(acc[A_TORQUE2]) * dt,
                      float(acc[A_FORCE2]) * dt,
                      acc[A_SQ:A_SQ + 4 * N_LEGS].reshape(4, N_LEGS).copy(),
                      int(acc[A_SAMPLES]),
                      float(np.mean(acc[A_X1:A_X1 + N_LEGS] - acc[A_X0:A_X0 + N_LEGS])),
                      float(acc[A_LAG]),
                      acc[A_EX:A_EX + 2 * N_LEGS].reshape(2, N_LEGS).copy(),
                      acc[A_E0:A_E0 + 2 * N_LEGS].reshape(2, N_LEGS).copy(),
                      acc[A_E1:A_E1 + 2 * N_LEGS].reshape(2, N_LEGS).copy(),
                      float(acc[A_SAMPLES]) * dt,
                      (float(acc[A_HY_MIN]), float(acc[A_HY_MAX])), float(acc[A_FY_MIN]))


def compute_indices(torque: np.ndarray, joint_vel: np.ndarray, hip_force: np.ndarray,
                    hip_pos: np.ndarray, hip_ref: np.ndarray, foot_pos: np.ndarray,
                    foot_ref: np.ndarray, dt: float) -> Indices:
    """Indices from (N+1, 6, 2) arrays of samples at the control ticks, spaced dt (s).

    torque T_m and joint_vel dtheta per joint; hip_force f_i, hip_pos/hip_ref and
    foot_pos/foot_ref per Cartesian axis (x, y). Row 0 only supplies x_iH(t_a).
    """
    return window_sums(torque, joint_vel, hip_force, hip_pos, hip_ref, foot_pos, foot_ref,
                       dt).indices()


def sums_from_obs(obs: np.ndarray, hip_ref: np.ndarray, foot_ref: np.ndarray,
                  dt: float) -> WindowSums:
    """:class:`WindowSums` from observation samples (N+1, 9, 6, 2) and refs (N+1, 6, 2)."""
    return window_sums(obs[:, O_TQ], obs[:, O_THV], obs[:, O_HF], obs[:, O_HP], hip_ref,
                       obs[:, O_FP], foot_ref, dt)


def indices_from_obs(obs: np.ndarray, hip_ref: np.ndarray, foot_ref: np.ndarray,
                     dt: float) -> Indices:
    """Indices from observation samples (N+1, 9, 6, 2) (hexapod_common.core.layout) and refs."""
    return sums_from_obs(obs, hip_ref, foot_ref, dt).indices()


def evaluation_window(p: HexapodParams, duration: float) -> tuple[float, float]:
    """(t_a, t_b): the last ``run.eval_cycles`` full gait cycles that fit in ``duration`` (s)."""
    period = p.cycle_time
    full = int(np.floor(duration / period + 1e-9))
    if full < p.run.eval_cycles:
        raise ParameterError("run.duration", duration,
                             f"at least run.eval_cycles x T = {p.run.eval_cycles * period:g} s")
    t_b = full * period
    return t_b - p.run.eval_cycles * period, t_b


def per_cycle_mean(cycles: Sequence[Indices]) -> Indices:
    """The indices of a segment of several gait cycles: every index's mean over its cycles
    (model.md, "The window": T_L and F_L are not additive over cycles, their square root
    makes the index of the union of N cycles about 1/sqrt(N) of one cycle's, so a segment
    reports the per-cycle mean; the drift per cycle is then the mean drift)."""
    if not cycles:
        raise ValueError("the per-cycle mean of no cycle")
    names = [f.name for f in fields(Indices)]
    return Indices(**{n: float(np.mean([getattr(c, n) for c in cycles])) for n in names})


def lag_growth(previous: Indices | None, current: Indices | None) -> float:
    """Growth of the hip lag from one gait cycle to the next (m per cycle; NaN if unknown)."""
    if previous is None or current is None:
        return float("nan")
    return current.lag_xH - previous.lag_xH


__all__ = ["DRIFT_NAMES", "INDEX_NAMES", "INDEX_UNITS", "Indices", "REPORTED_NAMES", "WindowSums",
           "compute_indices", "evaluation_window", "indices_from_obs", "lag_growth",
           "per_cycle_mean",
           "sums_from_accumulator", "sums_from_obs", "window_sums"]
