"""The paper's experiments on the batched engine: parameter sweeps (E2-E4) and the brute-force
gain search (E5). Pure functions of parameters; where the cases run is a backend
(:mod:`.parallel`).
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import Callable, Mapping, Sequence

import numpy as np

from hexapod_control.core.closed_loop import Case
from hexapod_sim.core.params import CONTROLLERS, HexapodParams

from .indices import INDEX_NAMES
from .parallel import Backend, InlineBackend, run_cases
from .simulate import Outcome

Progress = Callable[[int], None]


@dataclass(frozen=True)
class SweepResult:
    """Indices of every controller at every value of one swept parameter.

    ``outcomes[controller][k]`` belongs to ``values[k]``; ``fixed`` lists the other
    parameters that were set for the sweep (dotted name -> value).
    """

    variable: str
    values: np.ndarray
    outcomes: dict[str, list[Outcome]]
    fixed: dict[str, float] = field(default_factory=dict)

    def index(self, controller: str, name: str) -> np.ndarray:
        """One index over the sweep; NaN where the run diverged."""
        return np.array([getattr(o.indices, name) if o.indices else math.nan
                         for o in self.outcomes[controller]])

    def rows(self) -> list[dict[str, object]]:
        """Flat records (one per controller and value), for CSV/JSON."""
        out: list[dict[str, object]] = []
        for c, outs in self.outcomes.items():
            for v, o in zip(self.values, outs):
                row: dict[str, object] = {"controller": c, self.variable: float(v),
                                          "status": o.status, **self.fixed}
                row.update(o.indices.as_dict() if o.indices else
                           {k: math.nan for k in INDEX_NAMES + ("L",)})
                out.append(row)
        return out


def sweep(p: HexapodParams, variable: str, values: Sequence[float],
          controllers: Sequence[str] = CONTROLLERS, duration: float | None = None,
          backend: Backend | None = None, progress: Progress | None = None,
          **fixed: float) -> SweepResult:
    """Run every controller at every value of ``variable`` (a dotted parameter name).

    ``fixed`` sets other parameters for the whole sweep (names with '__' for '.').
    """
    fixed_dotted = {k.replace("__", "."): v for k, v in fixed.items()}
    base = p.with_values(**fixed_dotted) if fixed_dotted else p
    duration = base.run.duration if duration is None else duration
    cases = [Case(base.with_values(**{variable: float(v)}), c)
             for c in controllers for v in values]
    outs = run_cases(cases, duration, backend or InlineBackend(), progress=progress)
    n = len(values)
    by_ctrl = {c: outs[k * n:(k + 1) * n] for k, c in enumerate(controllers)}
    return SweepResult(variable, np.asarray(values, dtype=float), by_ctrl, fixed_dotted)


def ground_sweep(p: HexapodParams, percents: Sequence[float], t_max: float,
                 **kwargs: object) -> SweepResult:
    """E2/E4: all four ground parameters scaled by one percentage of the base values."""
    res = sweep(p, "ground.scale", np.asarray(percents, dtype=float) / 100.0,
                actuator__t_max=t_max, **kwargs)  # type: ignore[arg-type]
    return res


def t_max_sweep(p: HexapodParams, t_max_values: Sequence[float], ground_scale: float = 1.0,
                **kwargs: object) -> SweepResult:
    """E3: actuator saturation T_max swept at one ground."""
    return sweep(p, "actuator.t_max", t_max_values, ground__scale=ground_scale,
                 **kwargs)  # type: ignore[arg-type]


# -- E5: brute-force tuning ----------------------------------------------------------

GAIN_NAMES = ("kp1", "kd1", "kp2", "kd2")
DEFAULT_FACTORS = (0.5, 0.75, 1.0, 1.5, 2.0)


def default_grid(p: HexapodParams, controller: str,
                 factors: Sequence[float] = DEFAULT_FACTORS) -> dict[str, list[float]]:
    """Each gain of ``controller`` times each factor (5^4 = 625 sets by default)."""
    g = p.gains(controller)
    return {n: [getattr(g, n) * f for f in factors] for n in GAIN_NAMES}


def walking(o: Outcome, p: HexapodParams) -> bool:
    """A run walks if it did not diverge, covered 50-150 % of the commanded distance and
    kept the hips within 20 % of the body height (RMS per leg)."""
    if o.indices is None:
        return False
    expected = p.gait.velocity * p.cycle_time * p.run.eval_cycles
    return (0.5 * expected <= o.indices.L <= 1.5 * expected
            and o.indices.eps_yH / 6.0 <= 0.2 * p.gait.body_height)


def hip_score(o: Outcome) -> float:
    """E5's objective: eps_xH + eps_yH over the evaluation window (m)."""
    assert o.indices is not None
    return o.indices.eps_xH + o.indices.eps_yH


@dataclass(frozen=True)
class TuneResult:
    """Outcome of the brute-force search for one architecture."""

    controller: str
    grid: dict[str, list[float]]
    gains: list[dict[str, float]]
    outcomes: list[Outcome]
    scores: np.ndarray          # NaN for rejected sets
    rejected_diverged: int
    rejected_not_walking: int
    best: dict[str, float]
    best_score: float
    reference: dict[str, float]  # the params file's (Table I) gains
    reference_score: float       # NaN if Table I's gains do not walk

    @property
    def improvement(self) -> float:
        """Fraction by which the best beats the reference score (0.25 = 25 % lower)."""
        return 1.0 - self.best_score / self.reference_score


def select_best(gains: Sequence[Mapping[str, float]], outcomes: Sequence[Outcome],
                p: HexapodParams) -> tuple[int, np.ndarray, int, int]:
    """Index of the best walking set, the scores (NaN if rejected), and the counts of sets
    rejected as diverged and as not walking. Raises ValueError if none walks."""
    scores = np.full(len(outcomes), np.nan)
    diverged = not_walking = 0
    for k, o in enumerate(outcomes):
        if o.indices is None:
            diverged += 1
        elif not walking(o, p):
            not_walking += 1
        else:
            scores[k] = hip_score(o)
    if np.all(np.isnan(scores)):
        raise ValueError(f"no gain set of {len(gains)} walks: {diverged} diverged, "
                         f"{not_walking} did not walk")
    return int(np.nanargmin(scores)), scores, diverged, not_walking


def tune(p: HexapodParams, controller: str, grid: Mapping[str, Sequence[float]] | None = None,
         duration: float | None = None, backend: Backend | None = None,
         progress: Progress | None = None) -> TuneResult:
    """E5: evaluate every gain set of ``grid`` (gain name -> values; missing gains keep the
    params file's value), reject diverged and non-walking runs, rank the rest by
    eps_xH + eps_yH, and compare the best with the params file's gains."""
    grid = {k: list(v) for k, v in (grid or default_grid(p, controller)).items()}
    for name in grid:
        if name not in GAIN_NAMES + ("kf",):
            raise ValueError(f"unknown gain {name!r}: one of {', '.join(GAIN_NAMES + ('kf',))}")
    duration = p.run.duration if duration is None else duration
    names = list(grid)
    gains = [dict(zip(names, combo)) for combo in itertools.product(*grid.values())]
    ref_gains = {n: getattr(p.gains(controller), n) for n in names}
    cases = [Case(p.with_values(**{f"{controller}.{n}": v for n, v in g.items()}), controller)
             for g in gains]
    cases.append(Case(p, controller))
    outs = run_cases(cases, duration, backend or InlineBackend(), progress=progress)
    ref_out = outs.pop()
    best, scores, diverged, not_walking = select_best(gains, outs, p)
    ref_score = hip_score(ref_out) if walking(ref_out, p) else math.nan
    return TuneResult(controller, grid, gains, outs, scores, diverged, not_walking,
                      gains[best], float(scores[best]), ref_gains, ref_score)


__all__ = ["DEFAULT_FACTORS", "GAIN_NAMES", "SweepResult", "TuneResult", "default_grid",
           "ground_sweep", "hip_score", "select_best", "sweep", "t_max_sweep", "tune",
           "walking"]
