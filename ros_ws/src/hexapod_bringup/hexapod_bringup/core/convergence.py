"""dt convergence of the indices (model.md, "Time integration").

A case is rerun at dt/2 and dt/4 with the same control period (the controller, its sampling
and the zero-order hold are unchanged; only the physics is refined). It is *converged* when
every index moves by less than 1 % from dt/2 to dt/4, or, for the tracking errors, by less
than 1 mm if that is larger. The reported number stays the one at the params file's dt; its
*band* is the range the index spans over dt, dt/2 and dt/4, which is what a claim's margin
is held against (:mod:`.claims`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

from hexapod_control.core.closed_loop import Case
from hexapod_common.core.params import HexapodParams

from hexapod_metrics.core.indices import INDEX_NAMES, Indices
from .parallel import Backend, InlineBackend, run_cases
from .simulate import Outcome

#: Physics steps of a check, as divisors of the params file's dt.
REFINEMENTS = (1, 2, 4)
#: Largest relative change dt/2 -> dt/4 of a converged index.
REL_TOL = 0.01
#: Tracking errors may instead move by less than this (m).
ABS_TOL_TRACKING = 1e-3
TRACKING = ("eps_xH", "eps_yH", "eps_xF", "eps_yF")
#: The same four errors with the drift taken out of the horizontal ones (docs/indices.md):
#: the stationary tracking errors the claims are also decided on.
STATIONARY_TRACKING = ("trk_xH", "eps_yH", "trk_xF", "eps_yF")
#: Lengths in m that share the tracking errors' 1 mm floor (the hip lag beside eq. 11 and
#: the detrended horizontal errors).
LENGTHS = TRACKING + ("lag_xH", "trk_xH", "trk_xF")
#: The drift speeds (m/s) may instead move by less than this: 0.01 mm per 1 s gait cycle,
#: 1 % of the base case's drift (a drift near zero, as PD-P&F's on soft ground, has no
#: relative change to speak of).
ABS_TOL_DRIFT = 1e-5
DRIFTS = ("drift_xH", "drift_xF")


def refined(p: HexapodParams, factor: int) -> HexapodParams:
    """``p`` with the physics step divided by ``factor``, the control period kept."""
    return p if factor == 1 else p.with_values(**{"sim.dt": p.sim.dt / factor})


def tolerance(name: str, value: float) -> float:
    """How far index ``name`` of magnitude ``value`` may move and still count as converged."""
    tol = REL_TOL * abs(value)
    if name in DRIFTS:
        return max(tol, ABS_TOL_DRIFT)
    return max(tol, ABS_TOL_TRACKING) if name in LENGTHS else tol


@dataclass(frozen=True)
class Convergence:
    """The outcomes of one case at dt, dt/2 and dt/4 (indices None where a run diverged)."""

    outcomes: tuple[Outcome, ...]

    @property
    def runs(self) -> tuple[Indices | None, ...]:
        """Indices at dt, dt/2, dt/4."""
        return tuple(o.indices for o in self.outcomes)

    @property
    def value(self) -> Indices | None:
        """The reported indices: the run at the params file's dt."""
        return self.runs[0]

    @property
    def diverged(self) -> bool:
        """True if any of the three runs blew up."""
        return any(r is None for r in self.runs)

    def at_cycle(self, k: int) -> "Convergence":
        """The same check scored on gait cycle ``k`` alone (:meth:`Outcome.at_cycle`)."""
        return Convergence(tuple(o.at_cycle(k) for o in self.outcomes))

    def change(self, name: str) -> float:
        """Relative change of index ``name`` from dt/2 to dt/4 (NaN if a run diverged)."""
        if self.diverged:
            return math.nan
        b, c = getattr(self.runs[1], name), getattr(self.runs[2], name)
        return abs(b - c) / abs(c) if c != 0 else (0.0 if b == c else math.inf)

    def index_converged(self, name: str) -> bool:
        """Index ``name`` moved less than its tolerance from dt/2 to dt/4."""
        if self.diverged:
            return False
        b, c = getattr(self.runs[1], name), getattr(self.runs[2], name)
        return bool(abs(b - c) < tolerance(name, c))

    @property
    def converged(self) -> bool:
        """Every one of the seven indices converged (and no run diverged)."""
        return all(self.index_converged(n) for n in INDEX_NAMES)

    def converged_except(self, skip: Sequence[str]) -> bool:
        """Every index but those of ``skip`` converged."""
        return all(self.index_converged(n) for n in INDEX_NAMES if n not in skip)

    def unconverged(self) -> list[str]:
        """Names of the indices that did not converge."""
        return [n for n in INDEX_NAMES if not self.index_converged(n)]

    def band(self, name: str) -> tuple[float, float]:
        """(lowest, highest) value of index ``name`` over dt, dt/2, dt/4 (NaNs if diverged)."""
        if self.diverged:
            return math.nan, math.nan
        vals = [getattr(r, name) for r in self.runs]
        return min(vals), max(vals)

    def width(self, name: str) -> float:
        """Width of :meth:`band` (the uncertainty that a margin must exceed)."""
        lo, hi = self.band(name)
        return hi - lo

    def as_dict(self) -> dict[str, object]:
        """JSON view: values at each step, changes, verdict."""
        return {"converged": self.converged, "unconverged": self.unconverged(),
                "runs": [r.as_dict() if r else None for r in self.runs],
                "change_dt2_dt4": {n: self.change(n) for n in INDEX_NAMES}}


def check_cases(cases: Sequence[Case], duration: float, backend: Backend | None = None,
                progress: Callable[[int], None] | None = None) -> list[Convergence]:
    """Run every case at dt, dt/2 and dt/4 (one batch) and judge each one's convergence.

    ``progress(n)`` counts finished runs (3 per case).
    """
    runs = [Case(refined(c.params, f), c.controller) for c in cases for f in REFINEMENTS]
    outs = run_cases(runs, duration, backend or InlineBackend(), progress=progress)
    k = len(REFINEMENTS)
    return [Convergence(tuple(outs[i * k:(i + 1) * k])) for i in range(len(cases))]


__all__ = ["ABS_TOL_DRIFT", "ABS_TOL_TRACKING", "DRIFTS",
           "Convergence", "LENGTHS", "REFINEMENTS", "REL_TOL", "STATIONARY_TRACKING", "TRACKING",
           "check_cases", "refined", "tolerance"]
