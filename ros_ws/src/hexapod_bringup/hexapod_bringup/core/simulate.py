"""Python API of the in-process engine: run a case (or a batch) and score it.

    >>> from hexapod_bringup.core.simulate import simulate
    >>> from hexapod_common.core.params import load_params
    >>> out = simulate(load_params(), "pd_pf")
    >>> out.indices.eps_xH
    >>> [c.drift_xH for c in out.outcome.cycles]   # every full gait cycle, from t = 0

Every run is scored per full gait cycle (cycle c spans [c T, (c + 1) T]); the evaluation
window's indices are those of its last ``run.eval_cycles`` cycles added up
(indices.WindowSums), so a claim can be checked at every window.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, Callable, Mapping, Sequence

from hexapod_control.core.closed_loop import Case, RunResult, run, score_batch, tick_count
from hexapod_common.core.params import HexapodParams
from hexapod_sim.core.uneven_ground import GroundDraws

from hexapod_metrics.core.indices import (Indices, WindowSums, evaluation_window,
                                         sums_from_accumulator, sums_from_obs)
from hexapod_metrics.core.walking import not_walking


@dataclass(frozen=True)
class Outcome:
    """Indices of one case over its evaluation window, or why there are none."""

    case: Case
    indices: Indices | None
    window: tuple[float, float]
    status: str  # "ok" | "diverged" | "fallen" (walking.py: not a walk; indices None)
    cycles: tuple[Indices | None, ...] = ()
    """The indices of every full gait cycle of the run, cycle 0 first (None for a cycle that
    was not a walk; none at all if the run diverged)."""
    reason: str = ""
    """Why the run has no indices (``fallen``: which check of walking.py failed, and when)."""

    @property
    def diverged(self) -> bool:
        """True if the run blew up (its indices are None)."""
        return self.status == "diverged"

    def at_cycle(self, k: int) -> "Outcome":
        """The same run scored on gait cycle ``k`` alone, [k T, (k + 1) T] (indices None, and
        status ``diverged`` or ``fallen``, where the run has no indices for that cycle)."""
        period = self.case.params.cycle_time
        ix = self.cycles[k] if 0 <= k < len(self.cycles) else None
        status = "ok" if ix is not None else ("diverged" if self.diverged else "fallen")
        return replace(self, indices=ix, status=status, window=(k * period, (k + 1) * period))


@dataclass(frozen=True)
class Simulation:
    """A single run with its indices (None if diverged)."""

    outcome: Outcome
    run: RunResult

    @property
    def indices(self) -> Indices | None:
        """Indices over the evaluation window."""
        return self.outcome.indices


def window_ticks(p: HexapodParams, duration: float) -> tuple[int, int]:
    """Tick indices (k_a, k_b) of the evaluation window of a run of ``duration`` s."""
    t_a, t_b = evaluation_window(p, duration)
    tick_count(p, duration)  # validates duration against the control period
    dt = p.sim.control_period
    return int(round(t_a / dt)), int(round(t_b / dt))


def cycle_ticks(p: HexapodParams) -> int:
    """Control ticks per gait cycle, M = T / Delta t."""
    return int(round(p.cycle_time / p.sim.control_period))


def _scored(case: Case, per_cycle: Sequence[WindowSums], window: tuple[float, float]
            ) -> Outcome:
    """The outcome of a run that did not diverge: each cycle's indices (None where it was not
    a walk) and the evaluation window's (its last ``run.eval_cycles`` cycles added up), or
    ``fallen`` if one of the window's cycles was not a walk."""
    p = case.params
    why = [not_walking(s, p) for s in per_cycle]
    cycles = tuple(None if w else s.indices() for s, w in zip(per_cycle, why))
    first = len(per_cycle) - p.run.eval_cycles
    for k in range(first, len(per_cycle)):
        if why[k]:
            return Outcome(case, None, window, "fallen", cycles,
                           f"{why[k]} in gait cycle {k} [{k * p.cycle_time:g}, "
                           f"{(k + 1) * p.cycle_time:g}] s")
    total = per_cycle[first]
    for more in per_cycle[first + 1:]:
        total = total + more
    return Outcome(case, total.indices(), window, "ok", cycles)


def simulate(p: HexapodParams, controller: str | None = None, duration: float | None = None,
             progress: Callable[[int, int], None] | None = None,
             switches: Sequence[tuple[float, str]] = (),
             param_changes: Sequence[tuple[float, Mapping[str, Any]]] = (),
             ground: GroundDraws | None = None) -> Simulation:
    """Run one case in process and score every full gait cycle and the evaluation window.

    ``switches``: (time s, controller) hand-overs during the run, ``param_changes``: (time
    s, {name: value}) live parameter changes, ``ground``: uneven ground draws (see
    closed_loop.run; montecarlo.simulate_on_ground draws them from a seed)."""
    controller = controller or p.run.controller
    duration = p.run.duration if duration is None else duration
    k_a, k_b = window_ticks(p, duration)
    r = run(p, controller, duration, progress, switches, param_changes, ground)
    window = (float(r.t[k_a]), float(r.t[k_b]))
    case = Case(p, controller)
    if r.diverged_at is not None:
        return Simulation(Outcome(case, None, window, "diverged"), r)
    m = cycle_ticks(p)
    per_cycle = [sums_from_obs(r.obs[a:a + m + 1], r.reference.hip[a:a + m + 1],
                               r.reference.foot[a:a + m + 1], p.sim.control_period)
                 for a in range(0, k_b, m)]
    return Simulation(_scored(case, per_cycle, window), r)


def evaluate_batch(cases: Sequence[Case], duration: float) -> list[Outcome]:
    """Run cases in parallel (one compiled batch) and score every full gait cycle of each
    on the fly (closed_loop.score_batch: the same sums as recording the cycles and scoring
    them), the evaluation window from its last cycles."""
    p0 = cases[0].params
    _, k_b = window_ticks(p0, duration)
    m = cycle_ticks(p0)
    res = score_batch(cases, duration, (0, k_b), windows=k_b // m)
    dt = p0.sim.control_period
    out = []
    for c, accs, ok in zip(res.cases, res.sums, res.ok):
        window = (k_b * dt - c.params.run.eval_cycles * c.params.cycle_time, k_b * dt)
        if not ok:
            out.append(Outcome(c, None, window, "diverged"))
            continue
        out.append(_scored(c, [sums_from_accumulator(acc, dt) for acc in accs], window))
    return out


__all__ = ["Outcome", "Simulation", "cycle_ticks", "evaluate_batch", "simulate",
           "window_ticks"]
