"""What the report's sections share: table cells with their dt-convergence marks, the table
of every index of a few checked cases, the comparison of two controllers beyond their bands,
a comparison decided on every gait cycle alone (core/windows.py), CSV rows, the rate's
name."""
from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Callable, Mapping, Sequence

from hexapod_common.core.params import HexapodParams
from hexapod_metrics.core.indices import INDEX_UNITS, REPORTED_NAMES

from . import plots
from .core import claims
from .core.claims import Measured
from .core.convergence import REFINEMENTS, Convergence
from .core.experiments import SweepResult
from .core.windows import WindowVerdict, decided_over_windows

ProgressFactory = Callable[[str, int], Callable[[int], None]]
RUNS = len(REFINEMENTS)  # runs per checked point

#: The indices that decide a claim (C1-C4 use tracking errors, T_L and torque steps; E_av
#: is reported beside T_L). F_L, the sampled hip force, decides none.
DECIDING = ("E_av", "T_L", "eps_xH", "eps_yH", "eps_xF", "eps_yF")
#: The hip errors, as the paper scores them and with the drift taken out (docs/indices.md).
HIP = ("eps_xH", "eps_yH")
HIP_STATIONARY = ("trk_xH", "eps_yH")


def write_rows(path: Path, rows: list[dict[str, object]]) -> None:
    """``rows`` as a CSV file (columns: the first row's keys)."""
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


def cell(m: Measured) -> str:
    """A table cell: the value at dt, '†' and the band when not dt-converged."""
    if m.diverged:
        return "diverged" if m.converged else "diverged at some dt †"
    s = f"{m.value:.4g}"
    return s if m.converged else f"{s} † ({m.lo:.4g}-{m.hi:.4g})"


def indices_table(points: Mapping[str, Mapping[str, Measured]],
                  convs: Mapping[str, Convergence]) -> list[str]:
    """Rows: index; columns: value (at dt) and change dt/2 -> dt/4 per controller."""
    head = "| index | unit | " + " | ".join(
        f"{plots.label(c)} | {plots.label(c)} dt/2→dt/4" for c in points) + " |"
    out = [head, "|" + "---|" * (2 + 2 * len(points))]
    for n in REPORTED_NAMES:
        cells = []
        for c, pt in points.items():
            ch = convs[c].change(n)
            cells += [cell(pt[n]), "-" if n == "lag_xH" else
                      ("diverged" if math.isnan(ch) else f"{100 * ch:.2g} %")]
        out.append(f"| {n} | {INDEX_UNITS[n]} | " + " | ".join(cells) + " |")
    verdicts = [f"{plots.label(c)} " + ("converged" if cv.converged else
                                          f"NOT converged ({', '.join(cv.unconverged())})")
                for c, cv in convs.items()]
    return out + ["", "dt convergence: " + "; ".join(verdicts) + ". † marks a number that "
                  "moves by 1 % or more (tracking errors: and by 1 mm or more) from dt/2 to "
                  "dt/4; the range after it spans dt, dt/2 and dt/4."]


def sweep_points(res: SweepResult) -> dict[str, list[dict[str, Measured]]]:
    """Every index of every checked point of a sweep, per controller."""
    assert res.convergence is not None
    return {c: [claims.point(cv) for cv in res.convergence[c]] for c in res.outcomes}


def better(pf: Mapping[str, Measured], pp: Mapping[str, Measured], names: Sequence[str]
           ) -> str:
    """'pd_pf better' if every index of ``names`` of ``pf`` is decidedly below ``pp``'s,
    'pd_p better' if one is decidedly above, else 'undecided' (claims.less)."""
    t = claims.all3(claims.less(pf[n], pp[n]) for n in names)
    return "undecided" if t is None else ("pd_pf better" if t else "pd_p better")


def better_over_windows(pf: Convergence, pp: Convergence, names: Sequence[str],
                        label: str = "") -> WindowVerdict:
    """:func:`better` decided on each gait cycle FIRST_WINDOW..LAST_WINDOW alone, each
    cycle's numbers with their own dt band (``pf``, ``pp``: checks of runs that long)."""
    return decided_over_windows(label, lambda k: better(
        claims.point(pf.at_cycle(k)), claims.point(pp.at_cycle(k)), names))


def paper_cycle(p: HexapodParams, duration: float) -> int:
    """The gait cycle the paper's window is, in a run of ``duration`` s: its last full one
    (a run of 3 s: cycle 2)."""
    return int(math.floor(duration / p.cycle_time + 1e-9)) - 1


def hz(rate: float | None) -> str:
    """'10 kHz'; 'none of the rates tested' for None."""
    if rate is None:
        return "none of the rates tested"
    return f"{rate / 1000:g} kHz"


__all__ = ["DECIDING", "HIP", "HIP_STATIONARY", "ProgressFactory", "RUNS", "better",
           "better_over_windows", "cell", "hz", "indices_table", "paper_cycle", "sweep_points",
           "write_rows"]
