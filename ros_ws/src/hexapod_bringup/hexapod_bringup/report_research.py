"""Report sections beyond the paper: E8 (uneven ground, Monte Carlo with intervals) and
E5 by CMA-ES next to the grid. Each returns its Markdown lines and a JSON-ready record."""
from __future__ import annotations

import math
from typing import Any, Callable, Mapping, Sequence

from hexapod_common.core.params import CONTROLLERS, HexapodParams

from .core.cmaes import tune_cmaes
from .core.experiments import TuneResult
from .core.montecarlo import decide, hip_errors, monte_carlo_grid
from .core.parallel import Backend

ProgressFactory = Callable[[str, int], Callable[[int], None]]


def _mean(values: Any) -> float:
    import numpy as np

    v = values[np.isfinite(values)]
    return float(np.mean(v)) if v.size else math.nan


def e8_section(p: HexapodParams, percents: Sequence[float], spreads: Sequence[float],
               t_max_values: Sequence[float], seeds: int, backend: Backend,
               progress: ProgressFactory) -> tuple[list[str], dict[str, Any]]:
    """E8: PD-P vs PD-P&F on uneven ground (spreads in %), ``seeds`` seeds per point."""
    a, b = CONTROLLERS[0], CONTROLLERS[1]
    total = len(percents) * len(spreads) * len(t_max_values) * seeds * 2
    grid = monte_carlo_grid(p, (a, b), list(range(seeds)), percents,
                            [s / 100.0 for s in spreads], t_max_values, backend=backend,
                            progress=progress("E8 uneven ground (runs)", total))
    md = ["## E8: uneven ground (ours)", "",
          "Each foot draws its ground factors at every touchdown: nominal x log-normal "
          "(median 1, spread = sigma of ln factor; one factor for K and B in x, one in y), "
          f"from seed k, the same for both controllers (common random numbers); {seeds} seeds "
          "per point. Hip errors eps_xH + eps_yH (m): mean over the seeds; the difference "
          "PD-P&F - PD-P with its paired Student t 95 % interval; the winner when the "
          "interval excludes 0; *seeds needed*: the smallest number of seeds whose interval "
          "would exclude 0 at the measured mean and spread of the differences. Runs at dt "
          "(not checked at dt/2, dt/4).", "",
          "| T_max (N m) | ground % | spread % | PD-P | PD-P&F | PD-P&F - PD-P | winner | "
          "seeds needed | diverged (PD-P, PD-P&F) |",
          "|---|---|---|---|---|---|---|---|---|"]
    doc = []
    for g in grid:
        d = decide(g.result, a, b)
        iv = d.difference
        diff = (f"{iv.mean:.4g} ± {iv.half_width:.2g}" if iv.n >= 2 else "n/a")
        md.append(f"| {g.t_max:g} | {g.ground_percent:g} | {100 * g.spread:g} | "
                  f"{_mean(hip_errors(g.result, a)):.4g} | {_mean(hip_errors(g.result, b)):.4g}"
                  f" | {diff} | {d.winner or 'undecided'} | {d.seeds_needed or 'n/a'} | "
                  f"{g.result.diverged(a)}, {g.result.diverged(b)} |")
        doc.append({"t_max": g.t_max, "ground_percent": g.ground_percent,
                    "spread": g.spread, "difference": iv.as_dict(), "winner": d.winner,
                    "seeds_needed": d.seeds_needed,
                    "diverged": {c: g.result.diverged(c) for c in (a, b)}})
    md += ["", "Replay any seed: `hexapod montecarlo --seeds 1 --first-seed K --ground G "
           "--spread S --t-max T` (bit for bit; its JSON lists every factor used).", ""]
    return md, {"points": doc, "seeds": seeds}


def cmaes_section(p: HexapodParams, grid: Mapping[str, TuneResult], budget: int,
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
    md.append("")
    return md, doc


__all__ = ["cmaes_section", "e8_section"]
