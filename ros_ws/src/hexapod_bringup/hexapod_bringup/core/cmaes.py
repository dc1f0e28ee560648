"""E5 by CMA-ES: the gains that minimise the hip errors, found without a grid.

Same objective as the grid tuner (experiments.tune): trk_xH + eps_yH (m) over the
evaluation window; diverged and non-walking runs are rejected (they get
:data:`REJECTED_SCORE`, worse than any walking set, so CMA-ES ranks them last).

Search space: x_j = ln(gain_j / gain_j of the params file), so every gain moves by factors
and the step size sigma0 is a factor (default 0.8: about x/÷ 2.2 at the start), within
[ln LOW, ln HIGH] of the params file's value. The defaults (sigma0 0.8, CMA's own population
of 8 for four gains, 62 evaluations = a tenth of the default grid) were picked by trying
sigma0 0.3/0.5/0.8 and populations 6/8 on seeds 1-3 of E5 itself (so they are tuned on the
problem they are reported on). Each generation's candidates run as one set
of cases on a backend (parallel.run_cases: the process pool or Dask); a run of ``budget``
evaluations stops after the last whole generation that fits.

Why the ``cma`` package (N. Hansen's reference implementation) and not Optuna's CMA-ES
sampler: ask/tell on a whole generation maps directly onto one parallel batch of cases;
it handles box bounds; it is seeded (option 'seed'), so a tuning run is reproducible and
gives the same gains on every backend; and it is one small pure-Python dependency.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from hexapod_common.core.params import HexapodParams
from hexapod_control.core.closed_loop import Case

from .experiments import GAIN_NAMES, hip_score, walking
from .parallel import Backend, InlineBackend, run_cases
from .simulate import Outcome

#: Objective of a rejected set (m): above any walking set's hip errors.
REJECTED_SCORE = 1e3
#: Bounds of every gain as factors of the params file's value.
LOW, HIGH = 0.05, 20.0

Objective = Callable[[list[np.ndarray]], list[float]]


@dataclass(frozen=True)
class SearchResult:
    """Best point found, its value, and every (point, value) evaluated, in order."""

    best_x: np.ndarray
    best_f: float
    xs: list[np.ndarray]
    fs: list[float]
    generations: int

    @property
    def evaluations(self) -> int:
        """Objective evaluations spent."""
        return len(self.fs)

    def best_after(self, n: int) -> float:
        """Best value among the first ``n`` evaluations."""
        return float(min(self.fs[:n]))


def cmaes_search(objective: Objective, x0: Sequence[float], sigma0: float, budget: int,
                 bounds: tuple[float, float], seed: int = 1, popsize: int | None = None,
                 progress: Callable[[int], None] | None = None) -> SearchResult:
    """Minimise ``objective`` (a whole generation at once: points -> values) by CMA-ES from
    ``x0`` with step ``sigma0`` within ``bounds`` (each coordinate), spending at most
    ``budget`` evaluations; ``progress(n)`` after each generation of n evaluations."""
    import cma

    if budget < 2:
        raise ValueError(f"--budget {budget}: at least 2 evaluations")
    if not sigma0 > 0:
        raise ValueError(f"sigma0 = {sigma0!r}: must be > 0")
    opts: dict[str, object] = {"seed": seed, "bounds": [bounds[0], bounds[1]],
                               "verbose": -9, "tolfun": 1e-12, "tolx": 1e-8}
    if popsize is not None:
        opts["popsize"] = popsize
    es = cma.CMAEvolutionStrategy(list(x0), sigma0, opts)
    lam = int(es.popsize)
    if lam > budget:
        raise ValueError(f"--budget {budget} is less than one generation ({lam} candidates)")
    xs: list[np.ndarray] = []
    fs: list[float] = []
    gens = 0
    while len(fs) + lam <= budget and not es.stop():
        cand = [np.asarray(x, dtype=float) for x in es.ask()]
        vals = [float(v) for v in objective(cand)]
        es.tell(cand, vals)
        xs += cand
        fs += vals
        gens += 1
        if progress is not None:
            progress(len(cand))
    k = int(np.argmin(fs))
    return SearchResult(xs[k], fs[k], xs, fs, gens)


def score(o: Outcome, p: HexapodParams) -> float:
    """E5's objective of one run; :data:`REJECTED_SCORE` if diverged or not walking."""
    return hip_score(o) if walking(o, p) else REJECTED_SCORE


@dataclass(frozen=True)
class CmaesTuneResult:
    """CMA-ES tuning of one controller: best gains and score, the params file's, the
    number of evaluations and how many of them were rejected."""

    controller: str
    names: tuple[str, ...]
    best: dict[str, float]
    best_score: float
    reference: dict[str, float]
    reference_score: float
    evaluations: int
    rejected: int
    search: SearchResult

    @property
    def improvement(self) -> float:
        """Fraction by which the best beats the params file's score."""
        return 1.0 - self.best_score / self.reference_score


#: Parameters searched on a logistic scale inside their open range (the order of PD^alpha's
#: derivative): x = 0 is the params file's value, x -> +-inf the range's ends; the same box
#: [ln LOW, ln HIGH] as the gains' log factors keeps it within about 5 % of the ends.
ORDER_RANGES = {"alpha": (0.0, 2.0)}


def _logistic(v0: float, bounds: tuple[float, float], x: float) -> float:
    """The value at search coordinate ``x`` of a parameter worth ``v0`` at x = 0, within
    ``bounds`` (open)."""
    lo, hi = bounds
    u = (v0 - lo) / (hi - lo)
    return lo + (hi - lo) / (1.0 + math.exp(-(math.log(u / (1.0 - u)) + x)))


def searchable(p: HexapodParams, controller: str) -> tuple[str, ...]:
    """What CMA-ES may search for ``controller``: the four gains, K_f, and the order alpha
    where the controller has one (PD^alpha)."""
    extra = tuple(n for n in ORDER_RANGES if hasattr(p.gains(controller), n))
    return GAIN_NAMES + ("kf",) + extra


def default_names(p: HexapodParams, controller: str) -> tuple[str, ...]:
    """The default search: the four gains, and alpha where the controller has one."""
    return GAIN_NAMES + tuple(n for n in ORDER_RANGES if hasattr(p.gains(controller), n))


def tune_cmaes(p: HexapodParams, controller: str, names: Sequence[str] = GAIN_NAMES,
               budget: int = 62, sigma0: float = 0.8, seed: int = 1,
               popsize: int | None = None, duration: float | None = None,
               backend: Backend | None = None,
               progress: Callable[[int], None] | None = None) -> CmaesTuneResult:
    """E5 by CMA-ES over the gains ``names`` of ``controller`` (log factors of the params
    file's gains, within [LOW, HIGH] times them; alpha on a logistic scale inside (0, 2):
    :data:`ORDER_RANGES`), at most ``budget`` evaluations (the
    params file's own set is run once more, for the comparison, outside the budget)."""
    allowed = searchable(p, controller)
    for n in names:
        if n not in allowed:
            raise ValueError(f"unknown gain {n!r}: one of {', '.join(allowed)}")
    if len(set(names)) != len(names) or not names:
        raise ValueError(f"--gains {','.join(names)!r}: each gain once, at least one")
    duration = p.run.duration if duration is None else duration
    g0 = {n: float(getattr(p.gains(controller), n)) for n in names}
    for n, v in g0.items():
        if not v > 0:
            raise ValueError(f"{controller}.{n} = {v:g}: CMA-ES searches factors of a "
                             f"positive gain")
    be = backend or InlineBackend()
    ranges = {n: ORDER_RANGES[n] for n in names if n in ORDER_RANGES}
    for n, (lo, hi) in ranges.items():
        if not lo < g0[n] < hi:
            raise ValueError(f"{controller}.{n} = {g0[n]:g}: must lie in ({lo:g}, {hi:g})")

    def gains_of(x: np.ndarray) -> dict[str, float]:
        return {n: (_logistic(g0[n], ranges[n], float(xj)) if n in ranges
                    else g0[n] * math.exp(float(xj))) for n, xj in zip(names, x)}

    def cases(points: Sequence[np.ndarray]) -> list[Case]:
        return [Case(p.with_values(**{f"{controller}.{n}": v for n, v in gains_of(x).items()}),
                     controller) for x in points]

    # one generation spread over every worker (inline: one batch on numba's threads)
    workers = max(1, int(getattr(be, "workers", 1)))

    def objective(points: list[np.ndarray]) -> list[float]:
        chunk = max(1, math.ceil(len(points) / workers))
        return [score(o, p) for o in run_cases(cases(points), duration, be, chunk)]

    res = cmaes_search(objective, [0.0] * len(names), sigma0, budget,
                       (math.log(LOW), math.log(HIGH)), seed, popsize, progress)
    ref = run_cases([Case(p, controller)], duration, be)[0]
    ref_score = hip_score(ref) if walking(ref, p) else math.nan
    return CmaesTuneResult(controller, tuple(names), gains_of(res.best_x), res.best_f, g0,
                           ref_score, res.evaluations,
                           sum(f >= REJECTED_SCORE for f in res.fs), res)


__all__ = ["CmaesTuneResult", "HIGH", "LOW", "REJECTED_SCORE", "SearchResult", "cmaes_search",
           "ORDER_RANGES", "default_names", "score", "searchable", "tune_cmaes"]
