"""The paper's claims C1-C4 (model.md, "What the paper claims") as explicit, checkable rules.

Each function takes experiment results and returns a :class:`Verdict` with the numbers that
decide it. The thresholds are ours (the paper gives none) and are stated in each rule.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping

import numpy as np

from .experiments import SweepResult
from .indices import Indices

TRACKING = ("eps_xH", "eps_yH", "eps_xF", "eps_yF")
#: C3: "large degradation" = the summed tracking errors at least this many times the T_max 400 value.
C3_FACTOR = 2.0
#: C4: "stability problems" = divergence, or errors or torque steps this many times worse.
C4_FACTOR = 2.0


@dataclass(frozen=True)
class Verdict:
    """One claim, whether it holds in our model, the rule and the deciding numbers."""

    claim: str
    statement: str
    holds: bool
    rule: str
    evidence: str


def _tracking_sum(idx: Indices | None) -> float:
    return math.inf if idx is None else sum(getattr(idx, n) for n in TRACKING)


def c1(pd_p: Indices, pd_pf: Indices) -> Verdict:
    """C1: base case, T_max 400: PD-P&F tracks hip and foot better and needs less torque."""
    better = {n: getattr(pd_pf, n) < getattr(pd_p, n) for n in TRACKING}
    less_torque = pd_pf.T_L < pd_p.T_L
    ev = "; ".join(f"{n} {getattr(pd_pf, n):.4g} vs {getattr(pd_p, n):.4g} m" for n in TRACKING)
    ev += f"; T_L {pd_pf.T_L:.4g} vs {pd_p.T_L:.4g}; E_av {pd_pf.E_av:.4g} vs {pd_p.E_av:.4g}"
    return Verdict("C1", "Base, T_max 400: PD-P&F tracks hip and foot better than PD-P and "
                   "needs less joint torque", all(better.values()) and less_torque,
                   "all four tracking errors and T_L of PD-P&F below PD-P's",
                   "PD-P&F vs PD-P: " + ev)


def c2(sweeps: Mapping[float, SweepResult]) -> Verdict:
    """C2: over the ground sweep at each T_max, PD-P&F's hip and foot errors below PD-P's."""
    parts, ok = [], True
    for t_max, res in sweeps.items():
        for n in TRACKING:
            a, b = res.index("pd_pf", n), res.index("pd_p", n)
            wins = np.where(np.isnan(a), False, np.isnan(b) | (a < b))
            ok &= bool(wins.all())
            losing = [f"{100 * v:.3g} %" for v, w in zip(res.values, wins) if not w]
            parts.append(f"T_max {t_max:g}, {n}: {wins.sum()}/{len(wins)} points" +
                         (f" (not at {', '.join(losing)})" if losing else ""))
    return Verdict("C2", "Ground sweep at T_max 400 and 170: PD-P&F's hip and foot errors "
                   "stay below PD-P's over the whole range", ok,
                   "every tracking error of PD-P&F below PD-P's at every ground percentage",
                   "; ".join(parts))


def c3(strong: Mapping[str, Indices | None], base: Mapping[str, Indices], t_max: float
       ) -> Verdict:
    """C3: T_max < 160: large degradation of the indices for both controllers."""
    ratios = {c: _tracking_sum(strong[c]) / _tracking_sum(base[c]) for c in base}
    ev = "; ".join(f"{c}: tracking errors x{r:.3g} (eps_xH {_fmt(strong[c], 'eps_xH')} vs "
                   f"{base[c].eps_xH:.4g} m)" for c, r in ratios.items())
    return Verdict("C3", "T_max < 160: large degradation of the indices for both controllers",
                   all(r >= C3_FACTOR for r in ratios.values()),
                   f"at T_max {t_max:g} the summed tracking errors are >= {C3_FACTOR:g}x "
                   "their T_max 400 value for both controllers (or the run diverges)", ev)


def c4(ideal: SweepResult, torque_step: Mapping[str, Mapping[float, float]]) -> Verdict:
    """C4: T_max -> inf: PD-P&F shows stability problems on ground harder than the base.

    ``ideal`` is a ground sweep at T_max = inf that includes 100 %; ``torque_step[c][scale]``
    the largest tick-to-tick torque change (N m) of controller c at that ground scale.
    """
    scales = ideal.values
    k_base = int(np.argmin(np.abs(scales - 1.0)))
    hard = scales > 1.0
    err_pf = ideal.index("pd_pf", "eps_xH") + ideal.index("pd_pf", "eps_yH")
    diverged = [f"{100 * s:.3g} %" for s, e in zip(scales[hard], err_pf[hard]) if np.isnan(e)]
    growth = np.nanmax(err_pf[hard]) / err_pf[k_base] if np.any(~np.isnan(err_pf[hard])) \
        else math.inf
    steps = {s: torque_step["pd_pf"][s] / torque_step["pd_p"][s]
             for s in torque_step["pd_pf"] if s > 1.0}
    worst_step = max(steps.values()) if steps else 0.0
    holds = bool(diverged) or growth >= C4_FACTOR or worst_step >= C4_FACTOR
    ev = (f"PD-P&F diverged at {', '.join(diverged) or 'no ground'}; its hip errors on hard "
          f"ground reach x{growth:.3g} the 100 % value; its largest torque step is "
          + ", ".join(f"x{r:.3g} PD-P's at {100 * s:.3g} %" for s, r in sorted(steps.items())))
    return Verdict("C4", "T_max -> inf: PD-P&F shows stability problems (torque impulses at "
                   "foot impacts, growing errors) on ground harder than the base", holds,
                   f"on ground > 100 % at T_max = inf, PD-P&F diverges, or its hip errors grow "
                   f">= {C4_FACTOR:g}x its 100 % value, or its largest tick-to-tick torque step "
                   f"is >= {C4_FACTOR:g}x PD-P's", ev)


def _fmt(idx: Indices | None, name: str) -> str:
    return "diverged" if idx is None else f"{getattr(idx, name):.4g}"


__all__ = ["C3_FACTOR", "C4_FACTOR", "TRACKING", "Verdict", "c1", "c2", "c3", "c4"]
