"""E7 (ours): the authors' PD^α, tuned as the follow-up papers tune it (CMA-ES over Kp, Kd and
α, core/cmaes.py), against the tuned PD-P and PD-P&F (E5's best sets): the base case with
every index checked in dt, and the hip errors over the ground decided by the window rule
(each gait cycle 1-20 alone, on the paper's errors and on the stationary ones)."""
from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping, Sequence

from hexapod_common.core.params import HexapodParams, controller_group
from hexapod_control.core.closed_loop import Case

from . import plots
from .core import claims
from .core.cmaes import default_names, tune_cmaes
from .core.convergence import check_cases
from .core.experiments import ground_sweep, sweep
from .core.parallel import Backend
from .core.windows import FIRST_WINDOW, LAST_WINDOW
from .report_tables import (HIP, HIP_STATIONARY, RUNS, ProgressFactory, better_over_windows,
                            indices_table, paper_cycle)

#: E7's controllers: the paper's two and the authors' fractional PD^alpha (pd_alpha.py).
E7_CONTROLLERS = ("pd_p", "pd_pf", "pd_alpha")
#: How E7 words a cell of PD^α against a paper controller.
WORDS = {"pd_pf better": "better", "pd_p better": "worse", "undecided": "undecided",
         "depends on the window": "depends on the window"}


def tuned_params(p: HexapodParams, gains: Mapping[str, Mapping[str, float]]) -> HexapodParams:
    """``p`` with each controller's tuned gains (controller -> gain name -> value)."""
    return p.with_values(**{f"{controller_group(c)}.{n}": v for c, g in gains.items()
                            for n, v in g.items()})


def _gain_text(g: Mapping[str, float]) -> str:
    return ", ".join(f"{n} {v:.4g}" for n, v in g.items())


def e7_section(p400: HexapodParams, tuned: Mapping[str, Mapping[str, float]],
               scores: Mapping[str, float], percents: Sequence[float],
               t_max_values: Sequence[float], alphas: Sequence[float], budget: int, duration: float,
               window_duration: float, backend: Backend, progress: ProgressFactory,
               out: Path, drawer: plots.Drawer) -> tuple[list[str], dict[str, Any]]:
    """E7's Markdown lines and JSON record; its figures into ``out``. ``tuned``: E5's best
    gains of pd_p and pd_pf (``scores``: their objective); PD^α is tuned here by CMA-ES over
    its four gains and α with ``budget`` runs, on E5's objective."""
    names = default_names(p400, "pd_alpha")
    cma = tune_cmaes(p400, "pd_alpha", names, budget=budget, backend=backend,
                     progress=progress("E7 CMA-ES pd_alpha (runs)", budget))
    gains = {**{c: dict(tuned[c]) for c in ("pd_p", "pd_pf")}, "pd_alpha": dict(cma.best)}
    pt = tuned_params(p400, gains)
    g = pt.gains("pd_alpha")
    md = ["## E7: the authors' PD^α, tuned, against the tuned PD-P and PD-P&F (ours)", "",
          "PD^α (Silva, Machado & Lopes 2004): T_C = Kp e + Kd D^α e per joint, D^α by a "
          f"Grünwald-Letnikov series over the last {g.memory} control periods "
          "(`hexapod_control/core/pd_alpha.py`, a plug-in written against the controller API "
          "only), tuned as the follow-up papers tune it: CMA-ES over Kp1, Kd1, Kp2, Kd2 and "
          f"α ({cma.evaluations} runs, seed 1, sigma0 0.8, α on a logistic scale in (0, 2)) "
          "on E5's objective, trk_xH + eps_yH at T_max 400 N m on the base ground, from the "
          f"params file's set (score {cma.reference_score:.4g} m) to {cma.best_score:.4g} m. "
          "PD-P and PD-P&F run with E5's best sets (the lower of the grid's and CMA-ES's).", "",
          "| controller | tuned gains | score trk_xH + eps_yH (m) |", "|---|---|---|"]
    score = {**scores, "pd_alpha": cma.best_score}
    md += [f"| {plots.label(c)} | {_gain_text(gains[c])} | {score[c]:.4g} |"
           for c in E7_CONTROLLERS]
    md += ["", f"**Base case** (T_max = {p400.actuator.t_max:g} N m, base ground, tuned "
           "gains; every index at dt, dt/2 and dt/4):", ""]
    base = check_cases([Case(pt, c) for c in E7_CONTROLLERS], duration, backend,
                       progress("E7 base case (runs)", len(E7_CONTROLLERS) * RUNS))
    convs = dict(zip(E7_CONTROLLERS, base))
    md += indices_table({c: claims.point(cv) for c, cv in convs.items()}, convs) + [""]
    doc: dict[str, Any] = {"gains": gains, "cmaes": {
        "evaluations": cma.evaluations, "best_score": cma.best_score,
        "reference_score": cma.reference_score},
        "base": {c: cv.as_dict() for c, cv in convs.items()}}
    md += ["**Over the ground**, by the window rule: runs of "
           f"{window_duration:g} s at dt, dt/2 and dt/4, the hip errors of PD^α against each "
           f"paper controller decided on each gait cycle {FIRST_WINDOW}-{LAST_WINDOW} alone "
           "(*better*: both below beyond both convergence bands, *worse*: one above, else "
           "*undecided*; *depends on the window* when that changes from one cycle to "
           "another, the cycles named in `results.json`): on the paper's eps_xH, eps_yH and "
           "on the stationary trk_xH, eps_yH.", "",
           "| T_max (N m) | ground % | vs PD-P, paper's | vs PD-P, stationary | "
           "vs PD-P&F, paper's | vs PD-P&F, stationary |", "|---|---|---|---|---|---|"]
    figs, sweeps_doc = [], {}
    for t in t_max_values:
        res = ground_sweep(pt, percents, t, controllers=E7_CONTROLLERS,
                           duration=window_duration, backend=backend, check=True,
                           progress=progress(f"E7 ground sweep {t:g} N m (runs)",
                                             len(percents) * 3 * RUNS))
        assert res.convergence is not None
        rows = []
        for k, pct in enumerate(percents):
            a = res.convergence["pd_alpha"][k]
            vs = {(c, st): better_over_windows(a, res.convergence[c][k], judged, c)
                  for c in ("pd_p", "pd_pf")
                  for st, judged in (("paper", HIP), ("stationary", HIP_STATIONARY))}
            md.append(f"| {t:g} | {pct:g} | " + " | ".join(
                WORDS[v.status] for v in vs.values()) + " |")
            rows.append({"ground_percent": pct, **{f"vs_{c}_{st}": v.text()
                                                   for (c, st), v in vs.items()}})
        fname = f"fig_e7_ground_tmax{t:g}.png"
        drawer.sweep(res.at_cycle(paper_cycle(pt, duration)),
                     ("E_av", "eps_xH", "trk_xH", "eps_yH"), out / fname,
                     f"E7: tuned PD^α, PD-P, PD-P&F over the ground, T_max = {t:g} N m "
                     f"(gait cycle {paper_cycle(pt, duration)})")
        figs.append(f"![{fname}]({fname})")
        sweeps_doc[f"tmax{t:g}"] = rows
    md += [""] + figs + [""]
    alpha = sweep(pt, "pd_alpha.alpha", alphas, controllers=("pd_alpha",),
                  duration=duration, backend=backend, check=True,
                  progress=progress("E7 alpha (runs)", len(alphas) * RUNS))
    fname = "fig_e7_alpha.png"
    drawer.sweep(alpha, ("E_av", "T_L", "trk_xH", "eps_yH"), out / fname,
                 "E7: PD^α's indices against α (base case, its tuned gains)",
                 x_scale=1.0, x_label="α (order of the derivative)", log_x=False)
    md += [f"**Against α** (base case, the tuned Kp and Kd): ![{fname}]({fname})", ""]
    doc.update({"ground": sweeps_doc, "alpha": alpha.rows()})
    return md, doc


__all__ = ["E7_CONTROLLERS", "e7_section", "tuned_params"]
