"""Python API of the in-process engine: run a case (or a batch) and score it.

    >>> from hexapod_bringup.core.simulate import simulate
    >>> from hexapod_common.core.params import load_params
    >>> out = simulate(load_params(), "pd_pf")
    >>> out.indices.eps_xH
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Mapping, Sequence

from hexapod_control.core.closed_loop import Case, RunResult, run, score_batch, tick_count
from hexapod_common.core.params import HexapodParams
from hexapod_sim.core.uneven_ground import GroundDraws

from hexapod_metrics.core.indices import (Indices, evaluation_window, indices_from_obs,
                                         sums_from_accumulator)


@dataclass(frozen=True)
class Outcome:
    """Indices of one case over its evaluation window, or why there are none."""

    case: Case
    indices: Indices | None
    window: tuple[float, float]
    status: str  # "ok" | "diverged"

    @property
    def diverged(self) -> bool:
        """True if the run blew up (its indices are None)."""
        return self.status == "diverged"


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


def simulate(p: HexapodParams, controller: str | None = None, duration: float | None = None,
             progress: Callable[[int, int], None] | None = None,
             switches: Sequence[tuple[float, str]] = (),
             param_changes: Sequence[tuple[float, Mapping[str, Any]]] = (),
             ground: GroundDraws | None = None) -> Simulation:
    """Run one case in process and compute the indices of its evaluation window.

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
    sl = slice(k_a, k_b + 1)
    idx = indices_from_obs(r.obs[sl], r.reference.hip[sl], r.reference.foot[sl],
                           p.sim.control_period)
    return Simulation(Outcome(case, idx, window, "ok"), r)


def evaluate_batch(cases: Sequence[Case], duration: float) -> list[Outcome]:
    """Run cases in parallel (one compiled batch) and score each over its window, on the fly
    (closed_loop.score_batch: the same sums as recording the window and scoring it)."""
    p0 = cases[0].params
    res = score_batch(cases, duration, window_ticks(p0, duration))
    dt = p0.sim.control_period
    out = []
    for c, acc, ok in zip(res.cases, res.sums, res.ok):
        if not ok:
            out.append(Outcome(c, None, res.window, "diverged"))
            continue
        out.append(Outcome(c, sums_from_accumulator(acc, dt).indices(), res.window, "ok"))
    return out


__all__ = ["Outcome", "Simulation", "evaluate_batch", "simulate", "window_ticks"]
