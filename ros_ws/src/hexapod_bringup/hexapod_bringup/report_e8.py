"""E8 (ours): PD-P against PD-P&F on uneven ground, Monte Carlo over seeds with common random
numbers, decided by the paired interval of the stationary hip errors trk_xH + eps_yH on every
gait cycle 1-20 alone (the window rule, core/windows.py), and checked at dt/2 on the paper's
window."""
from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

from hexapod_common.core.params import CONTROLLERS, HexapodParams

from .core.convergence import refined
from .core.montecarlo import GridPoint, decide, hip_errors, monte_carlo_grid
from .core.parallel import Backend
from .core.windows import FIRST_WINDOW, LAST_WINDOW, decided_over_windows
from .report_tables import ProgressFactory, paper_cycle


def _mean(values: Any) -> float:
    v = values[np.isfinite(values)]
    return float(np.mean(v)) if v.size else math.nan


def e8_section(p: HexapodParams, percents: Sequence[float], spreads: Sequence[float],
               t_max_values: Sequence[float], seeds: int, duration: float,
               window_duration: float, backend: Backend, progress: ProgressFactory
               ) -> tuple[list[str], dict[str, Any]]:
    """E8: PD-P vs PD-P&F on uneven ground (spreads in %), ``seeds`` seeds per point: runs of
    ``window_duration`` at dt (every window), and of ``duration`` at dt/2 (the paper's
    window, checked in dt)."""
    a, b = CONTROLLERS[0], CONTROLLERS[1]
    total = len(percents) * len(spreads) * len(t_max_values) * seeds * 2
    args = ((a, b), list(range(seeds)), percents, [s / 100.0 for s in spreads], t_max_values)
    grid = monte_carlo_grid(p, *args, duration=window_duration, backend=backend,
                            progress=progress(f"E8 uneven ground, {window_duration:g} s (runs)",
                                              total))
    half = monte_carlo_grid(refined(p, 2), *args, duration=duration, backend=backend,
                            progress=progress("E8 uneven ground at dt/2 (runs)", total))
    first = paper_cycle(p, duration)
    md = ["## E8: uneven ground (ours)", "",
          "Each foot draws its ground factors at every touchdown: nominal x log-normal "
          "(median 1, spread = sigma of ln factor; one factor for K and B in x, one in y), "
          f"from seed k, the same for both controllers (common random numbers); {seeds} seeds "
          f"per point, runs of {window_duration:g} s at dt. Stationary hip errors trk_xH + "
          f"eps_yH (m) on gait cycle {first} (the paper's window): mean over the seeds; the "
          "difference PD-P&F - PD-P with its paired Student t 95 % interval; the winner when "
          "the interval excludes 0. *Every window*: the same decision on each gait cycle "
          f"{FIRST_WINDOW}-{LAST_WINDOW} alone (the winner if it is the same in every one, "
          f"else where it changes); *cycle 10 / 20*: the winner there (runs twice as long "
          f"apart); *dt/2*: the winner on cycle {first} of runs at dt/2 (the same seeds); "
          "*seeds needed*: the smallest number of seeds whose interval would exclude 0 at the "
          "measured mean and spread of the differences.", "",
          "| T_max (N m) | ground % | spread % | PD-P | PD-P&F | PD-P&F - PD-P | winner | "
          "every window | cycle 10 / 20 | dt/2 | seeds needed | diverged (PD-P, PD-P&F) |",
          "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    doc = []

    def winner(g: GridPoint, k: int) -> str:
        return decide(g.result.at_cycle(k), a, b).winner or "undecided"

    same_10_20 = 0
    for g, h in zip(grid, half):
        res = g.result.at_cycle(first)
        d = decide(res, a, b)
        iv = d.difference
        diff = (f"{iv.mean:.4g} ± {iv.half_width:.2g}" if iv.n >= 2 else "n/a")
        every = decided_over_windows("E8", lambda k, g=g: winner(g, k))
        w10, w20 = winner(g, 10), winner(g, 20)
        same_10_20 += w10 == w20
        dh = decide(h.result, a, b).winner or "undecided"
        md.append(f"| {g.t_max:g} | {g.ground_percent:g} | {100 * g.spread:g} | "
                  f"{_mean(hip_errors(res, a)):.4g} | {_mean(hip_errors(res, b)):.4g}"
                  f" | {diff} | {d.winner or 'undecided'} | {every.text()} | {w10} / {w20} | "
                  f"{dh} | {d.seeds_needed or 'n/a'} | "
                  f"{res.diverged(a)}, {res.diverged(b)} |")
        doc.append({"t_max": g.t_max, "ground_percent": g.ground_percent,
                    "spread": g.spread, "difference": iv.as_dict(), "winner": d.winner,
                    "every_window": every.text(), "window_winners": list(every.statuses),
                    "winner_dt2": dh, "seeds_needed": d.seeds_needed,
                    "diverged": {c: res.diverged(c) for c in (a, b)}})
    md += ["", f"The winner at cycle 10 is the winner at cycle 20 at {same_10_20}/{len(grid)} "
           "points. Replay any seed: `hexapod montecarlo --seeds 1 --first-seed K --ground G "
           "--spread S --t-max T` (bit for bit; its JSON lists every factor used).", ""]
    return md, {"points": doc, "seeds": seeds, "same_winner_10_20": same_10_20}


__all__ = ["e8_section"]
