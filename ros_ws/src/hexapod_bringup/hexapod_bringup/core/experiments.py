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
from hexapod_common.core.params import CONTROLLERS, HexapodParams, controller_group

from .convergence import Convergence, check_cases
from hexapod_metrics.core.indices import INDEX_NAMES, REPORTED_NAMES
from .parallel import Backend, InlineBackend, run_cases
from .simulate import Outcome

Progress = Callable[[int], None]


@dataclass(frozen=True)
class SweepResult:
    """Indices of every controller at every value of one swept parameter.

    ``outcomes[controller][k]`` belongs to ``values[k]``; ``fixed`` lists the other
    parameters that were set for the sweep (dotted name -> value). ``convergence`` (when
    the sweep was run with ``check=True``) holds each point's dt / dt/2 / dt/4 check.
    """

    variable: str
    values: np.ndarray
    outcomes: dict[str, list[Outcome]]
    fixed: dict[str, float] = field(default_factory=dict)
    convergence: dict[str, list[Convergence]] | None = None

    def index(self, controller: str, name: str) -> np.ndarray:
        """One index over the sweep; NaN where the run diverged."""
        return np.array([getattr(o.indices, name) if o.indices else math.nan
                         for o in self.outcomes[controller]])

    @property
    def checked(self) -> bool:
        """True if every point carries a convergence check."""
        return self.convergence is not None

    def converged(self, controller: str, name: str | None = None) -> np.ndarray:
        """Per point: converged (every index, or only ``name``); all True if unchecked."""
        if self.convergence is None:
            return np.ones(len(self.values), dtype=bool)
        return np.array([cv.converged if name is None else cv.index_converged(name)
                         for cv in self.convergence[controller]])

    def band(self, controller: str, name: str) -> tuple[np.ndarray, np.ndarray]:
        """Per point (lowest, highest) of the index over dt, dt/2, dt/4 (the value itself if
        unchecked)."""
        if self.convergence is None:
            v = self.index(controller, name)
            return v, v
        lo, hi = zip(*(cv.band(name) for cv in self.convergence[controller]))
        return np.array(lo), np.array(hi)

    def at_cycle(self, k: int) -> "SweepResult":
        """The same sweep scored on gait cycle ``k`` alone (Outcome.at_cycle; its checks
        too): a sweep of long runs gives the paper's window of a shorter one, bit for bit,
        where the long run did not diverge."""
        outs = {c: [o.at_cycle(k) for o in v] for c, v in self.outcomes.items()}
        conv = (None if self.convergence is None else
                {c: [cv.at_cycle(k) for cv in v] for c, v in self.convergence.items()})
        return SweepResult(self.variable, self.values, outs, self.fixed, conv)

    def rows(self) -> list[dict[str, object]]:
        """Flat records (one per controller and value), for CSV/JSON."""
        out: list[dict[str, object]] = []
        for c, outs in self.outcomes.items():
            for v, o in zip(self.values, outs):
                row: dict[str, object] = {"controller": c, self.variable: float(v),
                                          "status": o.status, **self.fixed}
                row.update(o.indices.as_dict() if o.indices else
                           {k: math.nan for k in REPORTED_NAMES})
                out.append(row)
        if self.convergence is not None:
            convs = [cv for c in self.outcomes for cv in self.convergence[c]]
            for row, cv in zip(out, convs):
                row["converged"] = cv.converged
                row["unconverged"] = " ".join(cv.unconverged())
                row.update({f"change_{n}": cv.change(n) for n in INDEX_NAMES})
        return out


def sweep_cases(base: HexapodParams, variable: str, values: Sequence[float],
                controllers: Sequence[str] = CONTROLLERS) -> list[Case]:
    """The cases of a sweep: every controller (outer) at every value of ``variable`` (a
    dotted parameter name) on ``base``."""
    return [Case(base.with_values(**{variable: float(v)}), c)
            for c in controllers for v in values]


def sweep(p: HexapodParams, variable: str, values: Sequence[float],
          controllers: Sequence[str] = CONTROLLERS, duration: float | None = None,
          backend: Backend | None = None, progress: Progress | None = None,
          check: bool = False, **fixed: float) -> SweepResult:
    """Run every controller at every value of ``variable`` (a dotted parameter name).

    ``fixed`` sets other parameters for the whole sweep (names with '__' for '.').
    ``check``: also run every point at dt/2 and dt/4 (:mod:`.convergence`); ``progress``
    then counts three runs per point.
    """
    fixed_dotted = {k.replace("__", "."): v for k, v in fixed.items()}
    base = p.with_values(**fixed_dotted) if fixed_dotted else p
    duration = base.run.duration if duration is None else duration
    cases = sweep_cases(base, variable, values, controllers)
    n = len(values)
    conv: dict[str, list[Convergence]] | None = None
    if check:
        checks = check_cases(cases, duration, backend, progress)
        outs = [cv.outcomes[0] for cv in checks]
        conv = {c: checks[k * n:(k + 1) * n] for k, c in enumerate(controllers)}
    else:
        outs = run_cases(cases, duration, backend or InlineBackend(), progress=progress)
    by_ctrl = {c: outs[k * n:(k + 1) * n] for k, c in enumerate(controllers)}
    return SweepResult(variable, np.asarray(values, dtype=float), by_ctrl, fixed_dotted, conv)


def ground_sweep(p: HexapodParams, percents: Sequence[float], t_max: float,
                 **kwargs: object) -> SweepResult:
    """E2/E4: all four ground parameters scaled by one percentage of the base values."""
    res = sweep(p, "ground.scale", [float(x) / 100.0 for x in percents],
                actuator__t_max=t_max, **kwargs)  # type: ignore[arg-type]
    return res


def t_max_sweep(p: HexapodParams, t_max_values: Sequence[float], ground_scale: float = 1.0,
                **kwargs: object) -> SweepResult:
    """E3: actuator saturation T_max swept at one ground."""
    return sweep(p, "actuator.t_max", t_max_values, ground__scale=ground_scale,
                 **kwargs)  # type: ignore[arg-type]


# -- E6: control rate -----------------------------------------------------------------

#: E6's control rates (Hz): 0.5-10 kHz, each a whole number of 1e-4 s physics steps.
RATES_HZ = (500.0, 1000.0, 2000.0, 5000.0, 10000.0)


def control_period_of(rate_hz: float) -> float:
    """Control period (s) of a control rate (Hz)."""
    if not rate_hz > 0 or math.isinf(rate_hz):
        raise ValueError(f"control rate must be a positive number of Hz, got {rate_hz!r}")
    return 1.0 / rate_hz


@dataclass(frozen=True)
class RateResult:
    """E6: checked ground sweeps per (control rate Hz, T_max), both controllers."""

    rates: tuple[float, ...]
    t_max_values: tuple[float, ...]
    percents: tuple[float, ...]
    sweeps: dict[tuple[float, float], SweepResult]
    #: PD-P&F with its force loop in the drive (pd_pf.force_loop = drive) at the same
    #: (rate, T_max) keys, one Convergence per ground percentage
    drive: dict[tuple[float, float], list[Convergence]] = field(default_factory=dict)


def rate_experiment(p: HexapodParams, rates: Sequence[float], percents: Sequence[float],
                    t_max_values: Sequence[float], duration: float | None = None,
                    backend: Backend | None = None, progress: Progress | None = None,
                    drive: bool = True) -> RateResult:
    """E6: every control rate x ground percentage x T_max x both controllers, and (``drive``)
    PD-P&F with its force loop in the drive, each point checked at dt, dt/2 and dt/4 (one
    batch of all runs; ``progress`` counts runs)."""
    duration = p.run.duration if duration is None else duration
    keys = [(float(r), float(t)) for r in rates for t in t_max_values]
    scales = np.asarray(percents, dtype=float) / 100.0
    cases = []
    for rate, t_max in keys:
        q = p.with_values(**{"sim.control_period": control_period_of(rate),
                             "actuator.t_max": t_max})
        cases += [Case(q.with_values(**{"ground.scale": float(s)}), c)
                  for c in CONTROLLERS for s in scales]
    for rate, t_max in keys if drive else ():
        q = p.with_values(**{"sim.control_period": control_period_of(rate),
                             "actuator.t_max": t_max, "pd_pf.force_loop": "drive"})
        cases += [Case(q.with_values(**{"ground.scale": float(s)}), "pd_pf") for s in scales]
    checks = check_cases(cases, duration, backend, progress)
    n, per_key = len(scales), len(scales) * len(CONTROLLERS)
    first_drive = len(keys) * per_key
    drives = {key: list(checks[first_drive + j * n:first_drive + (j + 1) * n])
              for j, key in enumerate(keys)} if drive else {}
    sweeps = {}
    for j, key in enumerate(keys):
        block = checks[j * per_key:(j + 1) * per_key]
        conv = {c: block[k * n:(k + 1) * n] for k, c in enumerate(CONTROLLERS)}
        outs = {c: [cv.outcomes[0] for cv in conv[c]] for c in CONTROLLERS}
        sweeps[key] = SweepResult("ground.scale", scales, outs,
                                  {"sim.control_period": control_period_of(key[0]),
                                   "actuator.t_max": key[1]}, conv)
    return RateResult(tuple(float(r) for r in rates), tuple(float(t) for t in t_max_values),
                      tuple(float(x) for x in percents), sweeps, drives)


# -- E5: brute-force tuning ----------------------------------------------------------

GAIN_NAMES = ("kp1", "kd1", "kp2", "kd2")
DEFAULT_FACTORS = (0.5, 0.75, 1.0, 1.5, 2.0)


def default_grid(p: HexapodParams, controller: str,
                 factors: Sequence[float] = DEFAULT_FACTORS) -> dict[str, list[float]]:
    """Each gain of ``controller`` times each factor (5^4 = 625 sets by default)."""
    g = p.gains(controller)
    return {n: [getattr(g, n) * f for f in factors] for n in GAIN_NAMES}


def walking(o: Outcome, p: HexapodParams) -> bool:
    """A run walks if it did not diverge and its evaluation window was a walk
    (hexapod_metrics.core.walking: hips near H_B, feet above -5 cm, 50-150 % of the
    commanded distance; ``p`` is kept for the callers)."""
    return o.status == "ok"


#: E5's objective and E8's deciding number: the stationary hip errors trk_xH + eps_yH (m):
#: eps_xH with each leg's mean offset taken out (the offset grows with the drift, so
#: eps_xH + eps_yH favoured the gains that drift least in the run's length:
#: docs/indices.md). The drift is reported beside it.
HIP_OBJECTIVE = ("trk_xH", "eps_yH")


def hip_score(o: Outcome) -> float:
    """E5's objective: trk_xH + eps_yH over the evaluation window (m; :data:`HIP_OBJECTIVE`)."""
    assert o.indices is not None
    return float(sum(getattr(o.indices, n) for n in HIP_OBJECTIVE))


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
    #: with check=True: each set's dt / dt/2 / dt/4 check, and the reference set's
    convergence: list[Convergence] | None = None
    reference_convergence: Convergence | None = None

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
        if o.status == "diverged":
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
         progress: Progress | None = None, check: bool = False) -> TuneResult:
    """E5: evaluate every gain set of ``grid`` (gain name -> values; missing gains keep the
    params file's value), reject diverged and non-walking runs, rank the rest by
    trk_xH + eps_yH, and compare the best with the params file's gains. ``check``: every
    set also at dt/2 and dt/4 (ranked by its dt run; ``progress`` counts three runs a set)."""
    grid = {k: list(v) for k, v in (grid or default_grid(p, controller)).items()}
    for name in grid:
        if name not in GAIN_NAMES + ("kf",):
            raise ValueError(f"unknown gain {name!r}: one of {', '.join(GAIN_NAMES + ('kf',))}")
    duration = p.run.duration if duration is None else duration
    names = list(grid)
    gains = [dict(zip(names, combo)) for combo in itertools.product(*grid.values())]
    ref_gains = {n: getattr(p.gains(controller), n) for n in names}
    group = controller_group(controller)
    cases = [Case(p.with_values(**{f"{group}.{n}": v for n, v in g.items()}), controller)
             for g in gains]
    cases.append(Case(p, controller))
    convs: list[Convergence] | None = None
    if check:
        convs = check_cases(cases, duration, backend, progress)
        outs = [cv.outcomes[0] for cv in convs]
    else:
        outs = run_cases(cases, duration, backend or InlineBackend(), progress=progress)
    ref_out = outs.pop()
    ref_conv = convs.pop() if convs is not None else None
    best, scores, diverged, not_walking = select_best(gains, outs, p)
    ref_score = hip_score(ref_out) if walking(ref_out, p) else math.nan
    return TuneResult(controller, {k: list(v) for k, v in grid.items()}, gains, outs, scores,
                      diverged, not_walking,
                      gains[best], float(scores[best]), ref_gains, ref_score, convs, ref_conv)


__all__ = ["DEFAULT_FACTORS", "GAIN_NAMES", "RATES_HZ", "RateResult", "SweepResult",
           "HIP_OBJECTIVE", "TuneResult", "control_period_of", "default_grid", "ground_sweep",
           "hip_score",
           "rate_experiment", "select_best", "sweep", "sweep_cases", "t_max_sweep", "tune",
           "walking"]
