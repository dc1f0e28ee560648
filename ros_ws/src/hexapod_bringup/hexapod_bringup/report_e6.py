"""E6 (ours): how fast must the force loop be closed? Both controllers over control rates x
ground x T_max, every point checked in dt, and PD-P&F with its force loop in the drive. Each
cell is judged on the paper's window (the last gait cycle of a run of ``run.duration``) and,
by the report's window rule (core/windows.py), on every gait cycle 1-20 alone: on the paper's
errors, which grow with the drift, and on the stationary ones (docs/indices.md)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

from hexapod_common.core.params import HexapodParams
from hexapod_metrics.core.indices import INDEX_NAMES

from . import plots
from .core.convergence import STATIONARY_TRACKING, TRACKING, Convergence
from .core.experiments import RateResult, SweepResult, rate_experiment
from .core.parallel import Backend
from .core.windows import FIRST_WINDOW, LAST_WINDOW, WindowVerdict
from .report_tables import (DECIDING, HIP, HIP_STATIONARY, RUNS, ProgressFactory, better,
                            better_over_windows, hz, sweep_points, write_rows)


def _lowest_rate_from(rates: Sequence[float], ok: Mapping[float, bool]) -> float | None:
    """The lowest rate r such that ok holds at r and at every higher rate."""
    best = None
    for r in sorted(rates, reverse=True):
        if not ok[r]:
            break
        best = r
    return best



@dataclass(frozen=True)
class RateFindings:
    """What E6 says: per T_max and (rate, ground %) cell, who tracks better (all four
    errors, and the two hip errors alone) and whether the numbers converged; and the lowest
    rates from which each holds everywhere (None: not even at the highest rate)."""

    cells: dict[float, dict[tuple[float, float], str]]
    hip_cells: dict[float, dict[tuple[float, float], str]]
    converged: dict[float, dict[tuple[float, float], bool]]        # all seven indices
    converged_deciding: dict[float, dict[tuple[float, float], bool]]  # DECIDING only
    advantage_rate: float | None
    hip_advantage_rate: float | None
    converged_rate: float | None
    deciding_converged_rate: float | None


def rate_findings(e6: RateResult) -> RateFindings:
    """Judge every E6 point with C2's criterion (decided comparisons of tracking errors)."""
    ts = e6.t_max_values
    cells: dict[float, dict[tuple[float, float], str]] = {t: {} for t in ts}
    hip: dict[float, dict[tuple[float, float], str]] = {t: {} for t in ts}
    conv: dict[float, dict[tuple[float, float], bool]] = {t: {} for t in ts}
    conv_d: dict[float, dict[tuple[float, float], bool]] = {t: {} for t in ts}
    for (rate, t_max), res in e6.sweeps.items():
        assert res.convergence is not None
        pts = sweep_points(res)
        for k, pct in enumerate(e6.percents):
            key = (rate, pct)
            cells[t_max][key] = better(pts["pd_pf"][k], pts["pd_p"][k], TRACKING)
            hip[t_max][key] = better(pts["pd_pf"][k], pts["pd_p"][k], ("eps_xH", "eps_yH"))
            cvs = [res.convergence[c][k] for c in res.outcomes]
            conv[t_max][key] = all(cv.converged for cv in cvs)
            skip = [n for n in INDEX_NAMES if n not in DECIDING]
            conv_d[t_max][key] = all(cv.converged_except(skip) for cv in cvs)

    def everywhere(table: Mapping[float, Mapping[tuple[float, float], object]],
                   want: object) -> dict[float, bool]:
        return {r: all(table[t][(r, g)] == want for t in ts for g in e6.percents)
                for r in e6.rates}

    return RateFindings(cells, hip, conv, conv_d,
                        _lowest_rate_from(e6.rates, everywhere(cells, "pd_pf better")),
                        _lowest_rate_from(e6.rates, everywhere(hip, "pd_pf better")),
                        _lowest_rate_from(e6.rates, everywhere(conv, True)),
                        _lowest_rate_from(e6.rates, everywhere(conv_d, True)))


#: E6's drive rows: PD-P&F with its force loop in the drive is "within" the 10 kHz
#: over-topics number when E_av and T_L are within 1 % and the four tracking errors within
#: 1 mm (the controller issue's criterion).
DRIVE_REL, DRIVE_ABS_M = 0.01, 1e-3
DRIVE_REL_NAMES = ("E_av", "T_L")
DRIVE_ABS_NAMES = ("eps_xH", "eps_yH", "eps_xF", "eps_yF")


def drive_within(drive: Convergence, reference: Convergence) -> bool | None:
    """Whether a drive point's numbers (at dt) are within DRIVE_REL / DRIVE_ABS_M of the
    reference's (None if either run diverged)."""
    a, b = drive.value, reference.value
    if a is None or b is None:
        return None
    return (all(abs(getattr(a, n) - getattr(b, n)) <= DRIVE_REL * abs(getattr(b, n))
                for n in DRIVE_REL_NAMES)
            and all(abs(getattr(a, n) - getattr(b, n)) <= DRIVE_ABS_M for n in DRIVE_ABS_NAMES))


def _drive_rows(e6: RateResult) -> list[str]:
    """E6's drive rows: per rate, PD-P&F with its force loop in the drive against the
    highest rate's over-topics PD-P&F, and against its own numbers at the highest rate, at
    every (ground, T_max)."""
    if not e6.drive:
        return []
    top = max(e6.rates)
    n_pts = len(e6.percents) * len(e6.t_max_values)
    md = ["", f"**PD-P&F with its force loop in the drive** (`pd_pf.force_loop: drive`: kp = "
          "K_f Kp, kd = K_f Kd, k_force = K_f evaluated at every physics step; the controller "
          "sends set-points and gains at the control rate), against PD-P&F over topics at "
          f"{hz(top)} and against itself at {hz(top)}, same ground and T_max. *Within*: "
          "E_av and T_L within 1 %, the four tracking errors within 1 mm.", "",
          f"| rate | over topics within topics at {hz(top)} | drive within topics at "
          f"{hz(top)} | drive within drive at {hz(top)} | drive points converged "
          "(deciding indices) |", "|---|---|---|---|---|"]
    skip = [n for n in INDEX_NAMES if n not in DECIDING]
    counts: dict[float, tuple[int, int, int]] = {}
    for r in e6.rates:
        within_drive = within_topic = within_self = conv = 0
        for t in e6.t_max_values:
            ref = e6.sweeps[(top, t)].convergence
            topic = e6.sweeps[(r, t)].convergence
            assert ref is not None and topic is not None
            for k, cv in enumerate(e6.drive[(r, t)]):
                within_drive += bool(drive_within(cv, ref["pd_pf"][k]))
                within_topic += bool(drive_within(topic["pd_pf"][k], ref["pd_pf"][k]))
                within_self += bool(drive_within(cv, e6.drive[(top, t)][k]))
                conv += cv.converged_except(skip)
        md.append(f"| {hz(r)} | {within_topic}/{n_pts} | {within_drive}/{n_pts} | "
                  f"{within_self}/{n_pts} | {conv}/{n_pts} |")
        counts[r] = (within_topic, within_drive, within_self)
    low = 1000.0 if 1000.0 in counts else min(e6.rates)
    md += ["", f"At {hz(low)} the drive placement is within its own {hz(top)} numbers at "
           f"{counts[low][2]}/{n_pts} points, the over-topics loop within its {hz(top)} "
           f"numbers at {counts[low][0]}/{n_pts}: with the force loop in the drive the "
           "control rate matters far less. Against the force loop sampled at "
           f"{hz(top)} it is within at {counts[top][1]}/{n_pts} points even at {hz(top)}: "
           "the continuous force loop is a different controller where the two part (the "
           "per-point numbers: `e6_control_rate.csv`, column force_loop). The graph runs it "
           "by default in realtime mode at 1 kHz (`docs/graph.md`)."]
    return md


def _drive_sweep(res: SweepResult, drive: list[Convergence]) -> SweepResult:
    """``res`` with PD-P&F's points replaced by its force-loop-in-the-drive points."""
    assert res.convergence is not None
    outs = dict(res.outcomes, pd_pf=[cv.outcomes[0] for cv in drive])
    return SweepResult(res.variable, res.values, outs,
                       res.fixed,
                       dict(res.convergence, pd_pf=drive))


#: E6's four judgements at every window: (key, what it judges, the indices).
WINDOW_JUDGEMENTS = (("hip", "hip errors, paper's", HIP),
                     ("hip_stationary", "hip errors, stationary", HIP_STATIONARY),
                     ("all", "all four errors, paper's", TRACKING),
                     ("all_stationary", "all four errors, stationary", STATIONARY_TRACKING))


@dataclass(frozen=True)
class WindowFindings:
    """E6 by the window rule: per judgement (WINDOW_JUDGEMENTS), T_max and (rate, ground %),
    the cell decided on each gait cycle alone; and per judgement the lowest rate from which
    PD-P&F is better in every window at every point (None: not even at the highest)."""

    cells: dict[str, dict[float, dict[tuple[float, float], WindowVerdict]]]
    advantage_rate: dict[str, float | None]


def window_findings(e6w: RateResult) -> WindowFindings:
    """Judge every point of E6's long runs (checked at dt, dt/2, dt/4) on each gait cycle
    FIRST_WINDOW..LAST_WINDOW alone."""
    ts = e6w.t_max_values
    cells: dict[str, dict[float, dict[tuple[float, float], WindowVerdict]]] = {
        key: {t: {} for t in ts} for key, _, _ in WINDOW_JUDGEMENTS}
    for (rate, t_max), res in e6w.sweeps.items():
        assert res.convergence is not None
        for k, pct in enumerate(e6w.percents):
            pf, pp = res.convergence["pd_pf"][k], res.convergence["pd_p"][k]
            for key, _, names in WINDOW_JUDGEMENTS:
                cells[key][t_max][(rate, pct)] = better_over_windows(pf, pp, names, key)
    rates = {key: _lowest_rate_from(e6w.rates, {
        r: all(cells[key][t][(r, g)].status == "pd_pf better" for t in ts
               for g in e6w.percents) for r in e6w.rates}) for key, _, _ in WINDOW_JUDGEMENTS}
    return WindowFindings(cells, rates)


def _window_rows(e6w: RateResult, w: WindowFindings) -> list[str]:
    """The table of E6 by the window rule: per rate, the cells where PD-P&F is better in
    every window, those whose verdict depends on the window, per judgement."""
    n_pts = len(e6w.percents) * len(e6w.t_max_values)
    keys = [(t, g) for t in e6w.t_max_values for g in e6w.percents]
    md = ["", f"**Every window** (runs of {LAST_WINDOW + 1} cycles at dt, dt/2 and dt/4, each "
          f"cell decided on each gait cycle {FIRST_WINDOW}-{LAST_WINDOW} alone with the same "
          "rule and each cycle's own dt band): the points where PD-P&F is better in every "
          "window, and those whose verdict depends on the window; *paper's* "
          "judges eps_xH, eps_yH (and eps_xF, eps_yF), which grow with the drift, "
          "*stationary* trk_xH, eps_yH (and trk_xF, eps_yF).", "",
          "| rate | " + " | ".join(what for _, what, _ in WINDOW_JUDGEMENTS) + " |",
          "|---|" + "---|" * len(WINDOW_JUDGEMENTS)]
    for r in e6w.rates:
        row = []
        for key, _, _ in WINDOW_JUDGEMENTS:
            vs = [w.cells[key][t][(r, g)] for t, g in keys]
            row.append(f"{sum(v.status == 'pd_pf better' for v in vs)}/{n_pts} better, "
                       f"{sum(v.status == 'depends on the window' for v in vs)} depend")
        md.append(f"| {hz(r)} | " + " | ".join(row) + " |")
    md += ["", "By the window rule, PD-P&F's hip errors are below PD-P's at every point in "
           "every window from these rates on: **"
           f"{hz(w.advantage_rate['hip'])}** (paper's indices), **"
           f"{hz(w.advantage_rate['hip_stationary'])}** (stationary); all four errors: **"
           f"{hz(w.advantage_rate['all'])}** (paper's), **"
           f"{hz(w.advantage_rate['all_stationary'])}** (stationary)."]
    return md


def e6_section(p: HexapodParams, rates: Sequence[float], percents: Sequence[float],
               t_max_values: Sequence[float], duration: float, window_duration: float,
               backend: Backend, progress: ProgressFactory, out: Path, drawer: plots.Drawer
               ) -> tuple[list[str], RateFindings, WindowFindings]:
    """E6's runs (the paper's window, ``duration``, with the drive placement; every window,
    ``window_duration``), its CSV, figures and Markdown lines."""
    n6 = len(rates) * len(percents) * len(t_max_values) * 3 * RUNS
    e6 = rate_experiment(p, rates, percents, t_max_values, duration, backend,
                         progress("E6 control rate (runs)", n6))
    e6w = rate_experiment(p, rates, percents, t_max_values, window_duration, backend,
                          progress(f"E6 every window, {window_duration:g} s runs (runs)",
                                   n6 * 2 // 3), drive=False)
    findings = rate_findings(e6)
    wf = window_findings(e6w)
    write_rows(out / "e6_control_rate.csv",
               [{"rate_hz": r, "force_loop": "drive" if row["controller"] == "pd_pf"
                 and drive else "topic", **row}
                for drive in (False, True)
                for (r, t), res in e6.sweeps.items()
                for row in (_drive_sweep(res, e6.drive[(r, t)]) if drive else res).rows()
                if not drive or row["controller"] == "pd_pf"])
    return (_e6_section(e6, findings, out, 1.0 / p.sim.control_period, drawer, e6w, wf),
            findings, wf)


def _e6_section(e6: RateResult, f: RateFindings, out: Path, paper_rate: float,
                drawer: plots.Drawer, e6w: RateResult, w: WindowFindings) -> list[str]:
    md = ["## E6: how fast must the force loop be closed? (control rate, ours)", "",
          f"Control rates {', '.join(hz(r) for r in e6.rates)} × ground "
          f"{', '.join(f'{g:g}' for g in e6.percents)} % × T_max "
          f"{', '.join(f'{t:g}' for t in e6.t_max_values)} N m × both controllers; every point "
          "run at dt, dt/2 and dt/4 with the same control period. A cell is *PD-P&F better* "
          "when all four of its tracking errors are below PD-P's by more than both "
          "controllers' convergence bands, *PD-P better* when one of them is above by more "
          "than the bands, else *undecided*; the hip columns judge eps_xH and eps_yH alone. "
          "*Converged* counts points whose seven indices all converged; the deciding "
          "indices leave out F_L (the hip force sampled at the control ticks, which no "
          "claim uses).", ""]
    n_pts = len(e6.percents) * len(e6.t_max_values)
    md += ["| rate | PD-P&F better | PD-P better | undecided | hip errors: PD-P&F better | "
           "points converged (all 7) | points converged (deciding indices) |",
           "|---|---|---|---|---|---|---|"]
    keys = [(t, g) for t in e6.t_max_values for g in e6.percents]
    for r in e6.rates:
        cs = [f.cells[t][(r, g)] for t, g in keys]
        hs = [f.hip_cells[t][(r, g)] for t, g in keys]
        nc = sum(f.converged[t][(r, g)] for t, g in keys)
        nd = sum(f.converged_deciding[t][(r, g)] for t, g in keys)
        md.append(f"| {hz(r)} | {cs.count('pd_pf better')}/{n_pts} | "
                  f"{cs.count('pd_p better')}/{n_pts} | {cs.count('undecided')}/{n_pts} | "
                  f"{hs.count('pd_pf better')}/{n_pts} | {nc}/{n_pts} | {nd}/{n_pts} |")
    rng = (f"{e6.percents[0]:g}-{e6.percents[-1]:g} %, T_max "
           f"{' and '.join(f'{t:g}' for t in e6.t_max_values)} N m")
    md += ["", f"**Answer.** Over the whole ground range ({rng}), PD-P&F's hip errors are "
           f"below PD-P's, decided, from **{hz(f.hip_advantage_rate)}** on; all four of its "
           f"tracking errors from **{hz(f.advantage_rate)}** on. Every deciding index is "
           f"dt-converged at every point from **{hz(f.deciding_converged_rate)}** on, all "
           f"seven indices from **{hz(f.converged_rate)}** on."]
    md[-1] += (" Point by point (cell, convergence, every index at dt, dt/2 and dt/4): "
               "`e6_control_rate.csv` and `results.json`. That table and answer read the "
               "paper's window, the last gait cycle of a run; the next ones every window.")
    md += _window_rows(e6w, w)
    md += _drive_rows(e6)
    md += ["", f"The experiments E1-E5 below run at **{hz(paper_rate)}** "
           "(`sim.control_period` of the params file)"]
    if f.deciding_converged_rate is not None and paper_rate >= f.deciding_converged_rate:
        md[-1] += (f", which is at or above the {hz(f.deciding_converged_rate)} from which "
                   "E6 finds every deciding number dt-converged: the model's numbers there no "
                   "longer depend on the step size, as a continuous-time controller's would "
                   "not.")
    else:
        md[-1] += (": BELOW the rate from which E6 finds every deciding number "
                   f"dt-converged ({hz(f.deciding_converged_rate)}): expect undecided "
                   "numbers.")
    md.append("")
    for t in e6.t_max_values:
        fname = f"fig_e6_map_tmax{t:g}.png"
        drawer.draw(plots.advantage_map, e6.rates, e6.percents, f.cells[t],
                    f.converged_deciding[t], out / fname,
                    f"E6: who tracks better, T_max = {t:g} N m")
        md.append(f"![{fname}]({fname})")
    md.append("")
    links = []
    for t in e6.t_max_values:
        for n in INDEX_NAMES:
            fname = f"fig_e6_{n}_tmax{t:g}.png"
            drawer.draw(plots.rate_plot,
                        {r: plots.SweepCurves.of(e6.sweeps[(r, t)], (n,)) for r in e6.rates},
                        n, out / fname, f"E6: {n} vs control rate, T_max = {t:g} N m")
            links.append(f"[{n}, {t:g} N m]({fname})")
    md += ["Each index against the control rate: " + ", ".join(links) + ".", ""]
    return md




__all__ = ["DRIVE_ABS_M", "DRIVE_REL", "RateFindings", "WINDOW_JUDGEMENTS", "WindowFindings",
           "drive_within", "e6_section", "rate_findings", "window_findings"]
