"""E9 (ours): when is it measured. Every index of PD-P, PD-P&F and PD^α per gait cycle over 20
cycles, on the base case and over the ground at T_max 400 and 170 N m: which indices are
stationary, and for every comparison of PD-P&F with PD-P the cycle from which its sign no
longer changes (core/windows.py; docs/indices.md). Its runs, table, figure and verdict."""
from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, Sequence

import math

from hexapod_common.core.params import CONTROLLERS, HexapodParams
from hexapod_control.core.closed_loop import Case
from hexapod_metrics.core.indices import INDEX_UNITS

from .core import claims
from .core.claims import Measured, Verdict
from .core.convergence import STATIONARY_TRACKING, TRACKING, Convergence, check_cases
from .core.parallel import Backend, run_cases
from .core.simulate import Outcome
from .core.windows import (FIRST_WINDOW, FOLLOWED, LAST_WINDOW, STATIONARY_CYCLES,
                           WindowVerdict, over_windows, settling, stationary)

ProgressFactory = Callable[[str, int], Callable[[int], None]]

#: The controllers followed: the paper's two and the authors' PD^α.
E9_CONTROLLERS = ("pd_p", "pd_pf", "pd_alpha")
#: Cycles 0..20.
E9_DURATION = 21.0
#: The horizontal indices drawn against the cycle.
FIGURE_NAMES = ("eps_xH", "eps_xF", "trk_xH", "trk_xF", "drift_xH")
NAMES = {"pd_p": "PD-P", "pd_pf": "PD-P&F", "pd_alpha": "PD^α"}


def _figure(base: dict[str, Outcome], path: Path) -> Path:
    from .plots import PNG_FAST, _figure as new_figure

    fig = new_figure(figsize=(7.0, 2.0 * len(FIGURE_NAMES)))
    axes = fig.subplots(len(FIGURE_NAMES), 1, sharex=True)
    for ax, name in zip(axes, FIGURE_NAMES):
        for c, o in base.items():
            ks = [k for k, i in enumerate(o.cycles) if i is not None]
            ax.plot(ks, [getattr(o.cycles[k], name) for k in ks], marker=".", label=NAMES[c])
        ax.set_ylabel(f"{name} ({INDEX_UNITS[name]})")
        ax.legend(fontsize=8)
    axes[-1].set_xlabel("gait cycle")
    fig.suptitle("E9: horizontal indices per gait cycle (base case, T_max 400 N m)")
    fig.savefig(path, pil_kwargs=PNG_FAST)
    return path


def e9_section(p: HexapodParams, percents: Sequence[float], t_max_values: Sequence[float],
               out: Path, backend: Backend, progress: ProgressFactory
               ) -> tuple[list[str], dict[str, Any]]:
    """E9's Markdown lines and JSON record; its figure into ``out``."""
    points = [(100.0, 400.0)] + [(g, t) for t in t_max_values for g in percents
                                 if (g, t) != (100.0, 400.0)]
    cases = [Case(p.with_values(**{"ground.scale": g / 100.0, "actuator.t_max": t}), c)
             for g, t in points for c in E9_CONTROLLERS]
    outs = run_cases(cases, E9_DURATION, backend,
                     progress=progress("E9 20-cycle runs", len(cases)))
    k = len(E9_CONTROLLERS)
    by_point = {pt: dict(zip(E9_CONTROLLERS, outs[i * k:(i + 1) * k]))
                for i, pt in enumerate(points)}
    base = by_point[(100.0, 400.0)]
    fig = _figure(base, out / "e9_cycles.png")
    a, b = "pd_p", "pd_pf"
    md = ["## E9: when is it measured (ours)", "",
          f"Every index per gait cycle over cycles 0-{int(E9_DURATION) - 1} (runs of "
          f"{E9_DURATION:g} s, at dt). *Stationary*: cycle {STATIONARY_CYCLES[0]} and cycle "
          f"{STATIONARY_CYCLES[1]} agree within the dt tolerance (1 %, or 1 mm for lengths). "
          f"*PD-P&F vs PD-P*: the sign of the difference in each cycle from cycle "
          f"{FIRST_WINDOW} (cycle 0 starts from rest) and the cycle from which it no longer "
          "changes; a verdict read on an index whose sign changes after that depends on the "
          "window.", "",
          "| index | stationary (PD-P, PD-P&F, PD^α) | PD-P&F vs PD-P, base case |",
          "|---|---|---|"]
    doc: dict[str, Any] = {"base": {}, "points": []}
    for name in FOLLOWED:
        st = [stationary(base[c].cycles, name) for c in E9_CONTROLLERS]
        s = settling(base[a].cycles, base[b].cycles, name)
        md.append(f"| {name} | {', '.join('yes' if x else 'no' for x in st)} | "
                  f"{s.describe(NAMES[a], NAMES[b])} |")
        doc["base"][name] = {"stationary": dict(zip(E9_CONTROLLERS, st)),
                             "signs": list(s.signs), "from_cycle": s.from_cycle}
    md += ["", "Over the ground (T_max, ground %): the comparisons of PD-P&F with PD-P whose "
           "sign changes after cycle 1, and runs that were not a walk.", "",
           "| T_max (N m) | ground % | window-dependent comparisons | not a walk |",
           "|---|---|---|---|"]
    for (g, t), o in by_point.items():
        moving = []
        for name in FOLLOWED:
            s = settling(o[a].cycles, o[b].cycles, name)
            if s.window_dependent():
                moving.append(f"{name} (from cycle {s.from_cycle})")
        fell = [NAMES[c] for c in E9_CONTROLLERS if o[c].status != "ok"]
        md.append(f"| {t:g} | {g:g} | {', '.join(moving) or 'none'} | "
                  f"{', '.join(fell) or '-'} |")
        doc["points"].append({"t_max": t, "ground_percent": g, "window_dependent": moving,
                              "status": {c: o[c].status for c in E9_CONTROLLERS}})
    paper = [n for n in FOLLOWED[:7] if not all(doc["base"][n]["stationary"].values())]
    steady = [n for n in FOLLOWED if all(doc["base"][n]["stationary"].values())]
    moving_steady = sorted({m.split(" ")[0] for pt in doc["points"]
                            for m in pt["window_dependent"] if m.split(" ")[0] in steady})
    md += ["", f"![E9]({fig.name})", "",
           f"On the base case the paper's {', '.join(paper) or 'indices (none)'} are not "
           "stationary: they grow every cycle with the drift, so a verdict read on them "
           "depends on the window wherever the two controllers' drift and tracking pull in "
           "opposite directions (the tables name those comparisons and the cycle they settle "
           f"from). The stationary ones ({', '.join(steady)}) "
           + ("settle from cycle 1 at every point above." if not moving_steady else
              f"settle from cycle 1 except {', '.join(moving_steady)} at the points named: "
              "there the run has not reached its steady gait by cycle 1 (on soft ground the "
              "drift changes sign as the body settles)."), ""]
    return md, doc


def _points(convs: Sequence[Convergence], k: int) -> list[dict[str, Measured]]:
    return [claims.point(cv.at_cycle(k)) for cv in convs]


def claims_over_windows(p: HexapodParams, ground_percents: Sequence[float],
                        t_max_values: Sequence[float], strong_t_max: float,
                        ideal_percents: Sequence[float],
                        steps: dict[float, dict[str, Measured]],
                        impacts: dict[float, dict[str, Measured]], backend: Backend,
                        progress: ProgressFactory
                        ) -> tuple[list[WindowVerdict], list[WindowVerdict]]:
    """C1-C4 decided on each gait cycle FIRST_WINDOW..LAST_WINDOW alone, on the paper's
    tracking errors and on the stationary ones (STATIONARY_TRACKING), with the same rules and
    the same dt-convergence check as the report's claims (runs of E9_DURATION at dt, dt/2,
    dt/4). C4's torque steps and impact torques are whole-run numbers: taken as measured.

    ``t_max_values``: C2's sweeps (the first is the base case's 400 N m)."""
    base_p = p.with_values(**{"actuator.t_max": 400.0})
    groups: list[tuple[str, float, float]] = (
        [("base", 100.0, 400.0), ("strong", 100.0, strong_t_max)]
        + [("sweep", g, t) for t in t_max_values for g in ground_percents]
        + [("ideal", g, math.inf) for g in ideal_percents])
    cases = [Case(base_p.with_values(**{"ground.scale": g / 100.0, "actuator.t_max": t}), c)
             for _, g, t in groups for c in CONTROLLERS]
    convs = check_cases(cases, E9_DURATION, backend,
                        progress(f"Claims over cycles {FIRST_WINDOW}-{LAST_WINDOW} (runs)",
                                 3 * len(cases)))
    n = len(CONTROLLERS)
    by = {grp: dict(zip(CONTROLLERS, convs[i * n:(i + 1) * n]))
          for i, grp in enumerate(groups)}

    def decide(k: int, tracking: Sequence[str]) -> list[Verdict]:
        base = {c: claims.point(by[("base", 100.0, 400.0)][c].at_cycle(k)) for c in CONTROLLERS}
        strong = {c: claims.point(by[("strong", 100.0, strong_t_max)][c].at_cycle(k))
                  for c in CONTROLLERS}
        sweeps = {t: {c: _points([by[("sweep", g, t)][c] for g in ground_percents], k)
                      for c in CONTROLLERS} for t in t_max_values}
        ideal = {g / 100.0: {c: claims.point(by[("ideal", g, math.inf)][c].at_cycle(k))
                             for c in CONTROLLERS} for g in ideal_percents}
        return [claims.c1(base["pd_p"], base["pd_pf"], tracking),
                claims.c2(sweeps, [g / 100.0 for g in ground_percents], tracking),
                claims.c3(strong, base, strong_t_max, tracking),
                claims.c4(ideal, steps, impacts, tracking)]

    def claim(tracking: tuple[str, ...], j: int) -> Callable[[int], Verdict]:
        return lambda k: per_cycle[tracking][k][j]

    cycles = range(FIRST_WINDOW, LAST_WINDOW + 1)
    per_cycle: dict[tuple[str, ...], dict[int, list[Verdict]]] = {
        tr: {k: decide(k, tr) for k in cycles} for tr in (TRACKING, STATIONARY_TRACKING)}
    return ([over_windows(claim(TRACKING, j)) for j in range(4)],
            [over_windows(claim(STATIONARY_TRACKING, j)) for j in range(4)])


__all__ = ["E9_CONTROLLERS", "E9_DURATION", "claims_over_windows", "e9_section"]
