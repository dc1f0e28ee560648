"""E5: the gains that minimise the hip errors, by the paper's brute-force grid, by a search
over PD-P's illegible Kp1, and by CMA-ES, all on the stationary hip errors trk_xH + eps_yH
(eps_xH's offset grows with the drift, so eps_xH + eps_yH favoured the gains that drift least
in the run's length: docs/indices.md); and the check that the tuned gains are the same when
the window is at gait cycle 10 or 20 instead of the paper's."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from hexapod_common.core.params import CONTROLLERS, HexapodParams, controller_group
from hexapod_control.core.closed_loop import Case

from . import plots
from .core import claims
from .core.claims import Measured
from .core.cmaes import tune_cmaes
from .core.convergence import check_cases
from .core.experiments import HIP_OBJECTIVE, TuneResult, hip_score, tune
from .core.parallel import Backend, run_cases
from .core.simulate import Outcome
from .report_tables import RUNS, ProgressFactory, cell, hz, paper_cycle

#: The grid's best sets (by the paper's window) that are run again over 20 cycles.
RECHECKED = 10
#: The two later windows the tuned gains are compared at.
LATER_CYCLES = (10, 20)


@dataclass(frozen=True)
class Tuned:
    """E5's outcome per controller: the best gains found (the lower of the grid's and
    CMA-ES's, on the paper's window at dt) and their objective (m)."""

    gains: dict[str, dict[str, float]]
    scores: dict[str, float]


def _score_at(o: Outcome, k: int) -> float:
    """The objective on gait cycle ``k`` alone; NaN if the run has none there."""
    at = o.at_cycle(k)
    return hip_score(at) if at.status == "ok" else math.nan


def _with(p: HexapodParams, controller: str, gains: Mapping[str, float]) -> HexapodParams:
    group = controller_group(controller)
    return p.with_values(**{f"{group}.{n}": v for n, v in gains.items()})


def _recheck(p400: HexapodParams, tunes: Mapping[str, TuneResult],
             cma: Mapping[str, Mapping[str, Any]], duration: float, window_duration: float,
             backend: Backend, progress: ProgressFactory) -> tuple[list[str], dict[str, Any]]:
    """The grid's RECHECKED best sets and CMA-ES's best, run for ``window_duration`` and
    scored on the paper's cycle and on LATER_CYCLES: is the best the same set?"""
    first = paper_cycle(p400, duration)
    cycles = (first,) + LATER_CYCLES
    jobs: list[tuple[str, str, dict[str, float]]] = []
    for c, tr in tunes.items():
        order = [int(i) for i in np.argsort(np.where(np.isnan(tr.scores), np.inf, tr.scores))
                 if not math.isnan(tr.scores[i])][:RECHECKED]
        jobs += [(c, f"grid's {r + 1}.", dict(tr.gains[i])) for r, i in enumerate(order)]
        jobs.append((c, "CMA-ES's", dict(cma[c]["cmaes_gains"])))
    outs = run_cases([Case(_with(p400, c, g), c) for c, _, g in jobs], window_duration,
                     backend, progress=progress(f"E5 best sets over {window_duration:g} s "
                                                "(runs)", len(jobs)))
    md = ["", f"**Are the tuned gains the same at a later window?** The grid's {RECHECKED} "
          "best sets (by the paper's window) and CMA-ES's best, run again for "
          f"{window_duration:g} s at dt and scored on gait cycle {first} (the paper's window), "
          f"{LATER_CYCLES[0]} and {LATER_CYCLES[1]} alone:", "",
          f"| controller | best at cycle {first} | best at cycle {LATER_CYCLES[0]} | best at "
          f"cycle {LATER_CYCLES[1]} | the same set | largest change of a score from cycle "
          f"{LATER_CYCLES[0]} to {LATER_CYCLES[1]} (mm) |", "|---|---|---|---|---|---|"]
    doc: dict[str, Any] = {}
    for c in tunes:
        mine = [(name, o) for (cc, name, _), o in zip(jobs, outs) if cc == c]
        scores = {k: np.array([_score_at(o, k) for _, o in mine]) for k in cycles}
        best = {k: mine[int(np.nanargmin(v))][0] if np.isfinite(v).any() else "none walks"
                for k, v in scores.items()}
        change = float(np.nanmax(np.abs(scores[LATER_CYCLES[1]] - scores[LATER_CYCLES[0]])))
        same = len(set(best.values())) == 1
        md.append(f"| {plots.label(c)} | {best[first]} | {best[LATER_CYCLES[0]]} | "
                  f"{best[LATER_CYCLES[1]]} | {'yes' if same else '**no**'} | "
                  f"{1000 * change:.3g} |")
        doc[c] = {"best": {str(k): v for k, v in best.items()}, "same": same,
                  "largest_change_m": change,
                  "scores": {str(k): [None if math.isnan(x) else float(x) for x in v]
                             for k, v in scores.items()},
                  "sets": [name for name, _ in mine]}
    return md + [""], doc


def _cmaes_section(p: HexapodParams, grid: Mapping[str, TuneResult], budget: int,
                   backend: Backend, progress: ProgressFactory
                   ) -> tuple[list[str], dict[str, Any]]:
    """E5 by CMA-ES (core/cmaes.py, default settings, seed 1) next to the grid's best."""
    md = ["### E5 by CMA-ES", "",
          f"CMA-ES over ln(gain / params file's gain) of the four gains, sigma0 0.8, seed 1, "
          f"at most {budget} runs; same objective and rejection rules as the grid, at dt.", "",
          "| controller | grid: runs | grid: best (m) | CMA-ES: runs | CMA-ES: best (m) | "
          "CMA-ES runs / grid runs | CMA-ES vs grid |", "|---|---|---|---|---|---|---|"]
    doc = {}
    for c, tr in grid.items():
        res = tune_cmaes(p, c, budget=budget, backend=backend,
                         progress=progress(f"E5 CMA-ES {c} (runs)", budget))
        runs = len(tr.gains)
        gap = res.best_score / tr.best_score - 1.0
        verdict = ("reaches the grid's best" if gap <= 0 else
                   f"falls short by {100 * gap:.2g} %")
        if gap <= 0 and res.evaluations <= runs / 10:
            verdict += " with at most a tenth of its runs"
        md.append(f"| {c} | {runs} | {tr.best_score:.5g} | {res.evaluations} | "
                  f"{res.best_score:.5g} | {res.evaluations / runs:.3f} | {verdict} |")
        doc[c] = {"grid_runs": runs, "grid_best": tr.best_score,
                  "cmaes_runs": res.evaluations, "cmaes_best": res.best_score,
                  "cmaes_gains": res.best, "gap": gap}
    return md, doc


def e5_section(p400: HexapodParams, factors: Sequence[float], kp1_values: Sequence[float],
               budget: int, duration: float, window_duration: float, backend: Backend,
               progress: ProgressFactory) -> tuple[list[str], dict[str, Any], Tuned]:
    """E5's Markdown lines, its JSON record (tuning, pd_p_kp1, tuning_cmaes, tuning_windows)
    and the tuned gains (for E7)."""
    rate = 1.0 / p400.sim.control_period
    md = ["## E5: brute-force tuning (T_max = 400 N m)", "",
          f"At {hz(rate)}. Each gain of the params file times each factor of "
          f"{list(factors)}; diverged or non-walking runs are rejected; the "
          "score is the stationary hip errors trk_xH + eps_yH over the last cycle (at dt; "
          "eps_xH's offset grows with the drift, so eps_xH + eps_yH favoured the gains that "
          "drift least in the run's length: docs/indices.md); the best set and the "
          "params file's set are then checked at dt/2 and dt/4.", "",
          "| controller | sets | diverged | not walking | Kp1 | Kd1 | Kp2 | Kd2 | score (m) "
          "| params file's score (m) | better by |",
          "|---|---|---|---|---|---|---|---|---|---|---|"]
    tunes: dict[str, TuneResult] = {}
    for c in CONTROLLERS:
        grid = {g: [getattr(p400.gains(c), g) * f for f in factors]
                for g in ("kp1", "kd1", "kp2", "kd2")}
        total = int(np.prod([len(v) for v in grid.values()])) + 1
        tr = tune(p400, c, grid, duration=duration, backend=backend,
                  progress=progress(f"E5 tuning {c}", total))
        tunes[c] = tr
        bc, rc = check_cases([Case(_with(p400, c, tr.best), c), Case(p400, c)], duration,
                             backend)
        sb = claims.total([Measured.of(bc, n) for n in HIP_OBJECTIVE])
        sr = claims.total([Measured.of(rc, n) for n in HIP_OBJECTIVE])
        b = tr.best
        md.append(f"| {plots.label(c)} | {len(tr.gains)} | {tr.rejected_diverged} | "
                  f"{tr.rejected_not_walking} | {b['kp1']:.6g} | {b['kd1']:.6g} | "
                  f"{b['kp2']:.6g} | {b['kd2']:.6g} | {cell(sb)} | {cell(sr)} | "
                  f"{100 * tr.improvement:.3g} % |")
    # PD-P's Kp1: every value over 20 cycles at dt, dt/2, dt/4; read on each window
    first = paper_cycle(p400, duration)
    kp1 = tune(p400, "pd_p", {"kp1": list(kp1_values)}, duration=window_duration,
               backend=backend, check=True,
               progress=progress("E5 PD-P Kp1 search (runs)", (len(kp1_values) + 1) * RUNS))
    assert kp1.convergence is not None and kp1.reference_convergence is not None
    cells = []
    for cv in kp1.convergence:
        at = cv.at_cycle(first)
        m = claims.total([Measured.of(at, n) for n in HIP_OBJECTIVE])
        cells.append("rejected" if at.value is None else cell(m))
    best_kp1 = {}
    for k in (first,) + LATER_CYCLES:
        s = np.array([_score_at(o, k) for o in kp1.outcomes])
        best_kp1[k] = kp1_values[int(np.nanargmin(s))] if np.isfinite(s).any() else math.nan
    ref = _score_at(kp1.reference_convergence.outcomes[0], first)
    best_score = float(np.nanmin([_score_at(o, first) for o in kp1.outcomes]))
    md += ["", "PD-P's Kp1 is illegible in the paper. With the other PD-P gains at their "
           f"Table I values, the search over Kp1 at {hz(rate)} (runs of {window_duration:g} s "
           f"at dt, dt/2 and dt/4, the table on gait cycle {first}, the paper's window) gives:",
           "", "| Kp1 | " + " | ".join(f"{v:.4g}" for v in kp1_values) + " |",
           "|---|" + "---|" * len(kp1_values),
           "| trk_xH + eps_yH (m) | " + " | ".join(cells) + " |", "",
           f"Best Kp1 = **{best_kp1[first]:.6g}** (score {best_score:.4g} m; the params "
           f"file's {kp1.reference['kp1']:.6g} scores {ref:.4g} m); on gait cycle "
           f"{LATER_CYCLES[0]} alone the best is {best_kp1[LATER_CYCLES[0]]:.6g}, on cycle "
           f"{LATER_CYCLES[1]} {best_kp1[LATER_CYCLES[1]]:.6g}.", ""]
    cma_md, cma_doc = _cmaes_section(p400, tunes, budget, backend, progress)
    check_md, check_doc = _recheck(p400, tunes, cma_doc, duration, window_duration, backend,
                                   progress)
    md += cma_md + check_md
    gains, scores = {}, {}
    for c, tr in tunes.items():
        use_cma = cma_doc[c]["cmaes_best"] < tr.best_score
        gains[c] = dict(cma_doc[c]["cmaes_gains"] if use_cma else tr.best)
        scores[c] = float(cma_doc[c]["cmaes_best"] if use_cma else tr.best_score)
    doc = {"tuning": {c: {"best": t.best, "score": t.best_score,
                          "reference_score": t.reference_score,
                          "rejected_diverged": t.rejected_diverged,
                          "rejected_not_walking": t.rejected_not_walking}
                      for c, t in tunes.items()},
           "pd_p_kp1": {"values": list(kp1_values),
                        "scores": [None if math.isnan(s) else s for s in
                                   (_score_at(o, first) for o in kp1.outcomes)],
                        "best": best_kp1[first],
                        "best_at_cycle": {str(k): v for k, v in best_kp1.items()}},
           "tuning_cmaes": cma_doc, "tuning_windows": check_doc}
    return md, doc, Tuned(gains, scores)


__all__ = ["LATER_CYCLES", "RECHECKED", "Tuned", "e5_section"]
