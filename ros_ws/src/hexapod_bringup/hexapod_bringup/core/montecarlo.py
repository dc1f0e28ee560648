"""Monte Carlo over uneven ground, with common random numbers across controllers.

Seed k draws every foot's ground factors (hexapod_sim.core.uneven_ground) and gives the
same sequence to every controller, so the controllers are compared on the same ground
(common random numbers). Each index gets its mean over the seeds with a 95 % Student t
interval, and each controller after the first its paired difference to the first
(per-seed B - A, paired t interval: stats.py). Every run records the factors its feet
used, so seed k can be replayed bit for bit (:func:`simulate_on_ground`).

Runs are single in-process runs (closed_loop.run), one task each on a backend
(parallel.py): the process pool and Dask give the same numbers.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Sequence

import numpy as np

from hexapod_common.core.params import HexapodParams
from hexapod_metrics.core.indices import REPORTED_NAMES
from hexapod_sim.core.uneven_ground import GroundDraws, check_seed, check_spread, pairs_for

from .experiments import HIP_OBJECTIVE
from .parallel import Backend, InlineBackend
from .simulate import Simulation, simulate
from .stats import Interval, mean_interval, paired_interval

#: How often a run is repeated with twice the draws when a foot touched down more often
#: than drawn for (the first draws stay the same: same numbers until then).
MAX_REDRAWS = 8


def simulate_on_ground(p: HexapodParams, controller: str, seed: int, spread: float,
                       duration: float | None = None) -> Simulation:
    """One run on the uneven ground of ``seed`` with spread ``spread`` (sigma of ln factor).

    Draws enough factor pairs for every touchdown (reruns with twice as many if a foot
    touched down more often; the common prefix keeps the numbers). The same (seed, spread,
    params, controller) gives the same numbers, bit for bit."""
    seed, spread = check_seed(seed), check_spread(spread)
    duration = p.run.duration if duration is None else duration
    pairs = pairs_for(duration, p.cycle_time)
    for _ in range(MAX_REDRAWS):
        sim = simulate(p, controller, duration, ground=GroundDraws.draw(seed, spread, pairs))
        rec = sim.run.ground
        assert rec is not None
        if not rec.overflowed:
            return sim
        pairs *= 2
    raise ArithmeticError(f"seed {seed}: a foot touched down more than {pairs // 2} times in "
                          f"{duration:g} s (chattering contact)")


@dataclass(frozen=True)
class McTask:
    """One Monte Carlo run: parameters, controller, seed, spread (sigma), duration (s)."""

    params: HexapodParams
    controller: str
    seed: int
    spread: float
    duration: float


@dataclass(frozen=True)
class McRun:
    """What one run gives: status ('ok' | 'diverged'), indices (None if diverged) and the
    ground it used (uneven_ground.GroundRecord.as_dict)."""

    controller: str
    seed: int
    status: str
    indices: dict[str, float] | None
    ground: dict[str, Any]
    cycles: tuple[dict[str, float] | None, ...] = ()
    """Every full gait cycle's indices (None where it was not a walk; none if diverged)."""

    def value(self, name: str) -> float:
        """Index ``name``, NaN if the run diverged."""
        return math.nan if self.indices is None else self.indices[name]

    def at_cycle(self, k: int) -> "McRun":
        """The same run scored on gait cycle ``k`` alone (no indices where it has none)."""
        ix = self.cycles[k] if 0 <= k < len(self.cycles) else None
        status = "ok" if ix is not None else ("diverged" if self.status == "diverged"
                                              else "fallen")
        return McRun(self.controller, self.seed, status, ix, self.ground, self.cycles)


def run_task(task: McTask) -> McRun:
    """Run one task (module level: picklable for the process pool and Dask)."""
    sim = simulate_on_ground(task.params, task.controller, task.seed, task.spread,
                             task.duration)
    rec = sim.run.ground
    assert rec is not None
    idx = sim.indices.as_dict() if sim.indices is not None else None
    cycles = tuple(c.as_dict() if c is not None else None for c in sim.outcome.cycles)
    return McRun(task.controller, task.seed, sim.outcome.status, idx, rec.as_dict(), cycles)


@dataclass(frozen=True)
class MonteCarloResult:
    """Runs per controller, in seed order; intervals at ``level``."""

    controllers: tuple[str, ...]
    seeds: tuple[int, ...]
    spread: float
    ground_scale: float
    t_max: float
    duration: float
    runs: dict[str, list[McRun]]
    level: float = 0.95
    names: tuple[str, ...] = field(default=REPORTED_NAMES)

    def values(self, controller: str, name: str) -> np.ndarray:
        """Index ``name`` of ``controller`` per seed (NaN where diverged)."""
        return np.array([r.value(name) for r in self.runs[controller]])

    def interval(self, controller: str, name: str) -> Interval:
        """Mean of index ``name`` over the seeds that did not diverge, Student t interval."""
        return mean_interval(self.values(controller, name), self.level)

    def difference(self, a: str, b: str, name: str) -> Interval:
        """Paired difference b - a of index ``name`` over the seeds where both walked."""
        return paired_interval(self.values(a, name), self.values(b, name), self.level)

    def at_cycle(self, k: int) -> "MonteCarloResult":
        """The same runs scored on gait cycle ``k`` alone (McRun.at_cycle)."""
        return replace(self, runs={c: [r.at_cycle(k) for r in v] for c, v in self.runs.items()})

    def diverged(self, controller: str) -> int:
        """Seeds on which ``controller`` diverged."""
        return sum(r.status != "ok" for r in self.runs[controller])

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready: settings, intervals, differences and every run with its draws."""
        base = self.controllers[0]
        return {
            "method": "Student t intervals of the mean over seeds; paired t on per-seed "
                      "differences (common random numbers)",
            "level": self.level, "seeds": list(self.seeds), "spread": self.spread,
            "ground_scale": self.ground_scale, "t_max": self.t_max,
            "duration": self.duration, "controllers": list(self.controllers),
            "diverged": {c: self.diverged(c) for c in self.controllers},
            "intervals": {c: {n: self.interval(c, n).as_dict() for n in self.names}
                          for c in self.controllers},
            "differences": {f"{c}-{base}": {n: self.difference(base, c, n).as_dict()
                                            for n in self.names}
                            for c in self.controllers[1:]},
            "runs": [{"controller": r.controller, "seed": r.seed, "status": r.status,
                      "indices": r.indices, "ground": r.ground}
                     for c in self.controllers for r in self.runs[c]],
        }


def _checked(seeds: Sequence[int], controllers: Sequence[str]) -> list[int]:
    """The seeds as ints (distinct, each in range); ValueError on none or repeated ones."""
    out = [check_seed(s, "seed") for s in seeds]
    if len(set(out)) != len(out):
        raise ValueError("seeds must be distinct")
    if not controllers:
        raise ValueError("at least one controller")
    return out


def _run_all(tasks: Sequence[McTask], backend: Backend | None,
             progress: Callable[[int], None] | None) -> list[McRun]:
    """:func:`run_task` of every task on ``backend`` (default: this process), in order;
    ``progress(1)`` after each run."""
    out: list[McRun | None] = [None] * len(tasks)
    for k, r in (backend or InlineBackend()).calls(run_task, tasks):
        out[k] = r
        if progress is not None:
            progress(1)
    return [r for r in out if r is not None]


def monte_carlo(p: HexapodParams, controllers: Sequence[str], seeds: Sequence[int],
                spread: float, duration: float | None = None,
                backend: Backend | None = None,
                progress: Callable[[int], None] | None = None,
                level: float = 0.95) -> MonteCarloResult:
    """Run every controller on the ground of every seed (common random numbers) and
    collect the runs; ``progress(1)`` after each run."""
    spread = check_spread(spread)
    seeds = _checked(seeds, controllers)
    duration = p.run.duration if duration is None else duration
    done = _run_all([McTask(p, c, s, spread, duration) for c in controllers for s in seeds],
                    backend, progress)
    n = len(seeds)
    runs = {c: done[j * n:(j + 1) * n] for j, c in enumerate(controllers)}
    return MonteCarloResult(tuple(controllers), tuple(seeds), spread, p.ground.scale,
                            p.actuator.t_max, duration, runs, level)


# -- E8: which controller wins on uneven ground ---------------------------------------

#: E8's deciding number: the stationary hip errors trk_xH + eps_yH (m), E5's objective.
HIP = HIP_OBJECTIVE


@dataclass(frozen=True)
class Decision:
    """E8 at one point: the paired difference of the hip errors (b - a, m), who wins
    (the interval below 0: b; above: a; else None), and the seeds an interval excluding 0
    would need if the mean and spread of the differences stayed as measured (a planning
    figure, not a test: None if the mean difference is 0)."""

    difference: Interval
    winner: str | None
    seeds_needed: int | None


def hip_errors(res: MonteCarloResult, controller: str) -> np.ndarray:
    """trk_xH + eps_yH of ``controller`` per seed (m; NaN where diverged)."""
    total: np.ndarray = res.values(controller, HIP[0]) + res.values(controller, HIP[1])
    return total


def decide(res: MonteCarloResult, a: str, b: str) -> Decision:
    """Who has the lower hip errors on this ground, by the paired t interval of b - a."""
    d = paired_interval(hip_errors(res, a), hip_errors(res, b), res.level)
    winner = (b if d.high < 0.0 else a if d.low > 0.0 else None) if d.n >= 2 else None
    needed: int | None = None
    if d.n >= 2 and d.mean != 0.0:
        from .stats import t_quantile

        sd = d.half_width * math.sqrt(d.n) / t_quantile(0.5 + 0.5 * res.level, d.n - 1)
        n = 2
        while n < 100000 and t_quantile(0.5 + 0.5 * res.level, n - 1) * sd / math.sqrt(n) \
                >= abs(d.mean):
            n += 1
        needed = n
    return Decision(d, winner, needed)


@dataclass(frozen=True)
class GridPoint:
    """One E8 point: nominal ground (% of base), spread (sigma of ln factor), T_max (N m)."""

    ground_percent: float
    spread: float
    t_max: float
    result: MonteCarloResult


def monte_carlo_grid(p: HexapodParams, controllers: Sequence[str], seeds: Sequence[int],
                     ground_percents: Sequence[float], spreads: Sequence[float],
                     t_max_values: Sequence[float], duration: float | None = None,
                     backend: Backend | None = None,
                     progress: Callable[[int], None] | None = None,
                     level: float = 0.95) -> list[GridPoint]:
    """E8: :func:`monte_carlo` at every (ground %, spread, T_max), all runs in one pass
    over the backend (the same seeds, hence the same ground sequences, at every point)."""
    seeds = _checked(seeds, controllers)
    duration = p.run.duration if duration is None else duration
    points = [(float(g), check_spread(s), float(t)) for t in t_max_values
              for g in ground_percents for s in spreads]
    tasks = []
    for g, s, t in points:
        q = p.with_values(**{"ground.scale": g / 100.0, "actuator.t_max": t})
        tasks += [McTask(q, c, k, s, duration) for c in controllers for k in seeds]
    done = _run_all(tasks, backend, progress)
    n, per = len(seeds), len(seeds) * len(controllers)
    grid = []
    for j, (g, s, t) in enumerate(points):
        block = done[j * per:(j + 1) * per]
        runs = {c: block[i * n:(i + 1) * n] for i, c in enumerate(controllers)}
        grid.append(GridPoint(g, s, t, MonteCarloResult(
            tuple(controllers), tuple(seeds), s, g / 100.0, t, duration, runs, level)))
    return grid


__all__ = ["Decision", "GridPoint", "HIP", "MAX_REDRAWS", "McRun", "McTask",
           "MonteCarloResult", "decide", "hip_errors", "monte_carlo", "monte_carlo_grid",
           "run_task", "simulate_on_ground"]
