"""The paper's claims C1-C4 (model.md, "What the paper claims") as explicit, checkable rules.

Each rule is built from comparisons of numbers that carry a convergence check
(:class:`Measured`: the value at dt and the band it spans over dt, dt/2, dt/4). A comparison
is *decided* when both numbers are converged and the margin exceeds the two bands; else it is
undecided. A claim that needs all its comparisons (C1, C2, C3) fails if one decided comparison
fails, is undecided if none fails but one is undecided, and holds otherwise; a claim that
needs any one of its signs (C4) holds if one is decided true. The thresholds are ours (the
paper gives none) and are stated in each rule.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable, Mapping, Sequence

from .convergence import STATIONARY_TRACKING, TRACKING, Convergence
from hexapod_metrics.core.indices import REPORTED_NAMES

#: C3: "large degradation" = the summed tracking errors at least this many times the
#: T_max 400 value.
C3_FACTOR = 2.0
#: C4: "stability problems" = divergence, or errors or torque steps this many times worse.
C4_FACTOR = 2.0

HOLDS, FAILS, UNDECIDED = "holds", "fails", "undecided"
#: A three-valued truth: True, False, or None (undecided).
Tri = bool | None


@dataclass(frozen=True)
class Measured:
    """A number at dt with its band [lo, hi] over dt, dt/2, dt/4 and its convergence verdict.

    ``value`` NaN means the run diverged (at some step size, if ``converged`` is False).
    """

    value: float
    lo: float
    hi: float
    converged: bool

    @staticmethod
    def exact(value: float) -> "Measured":
        """A number without step-size uncertainty (an unchecked run taken at its word)."""
        return Measured(value, value, value, True)

    @staticmethod
    def of(conv: Convergence, name: str) -> "Measured":
        """Index ``name`` of a convergence check."""
        if all(r is None for r in conv.runs):  # diverged at every step size: decided
            return Measured(math.nan, math.nan, math.nan, True)
        idx = conv.value
        value = math.nan if idx is None else float(getattr(idx, name))
        lo, hi = conv.band(name)
        return Measured(value, lo, hi, conv.index_converged(name))

    @property
    def diverged(self) -> bool:
        """The run at dt blew up."""
        return math.isnan(self.value)

    def text(self, digits: int = 4) -> str:
        """'0.0274' or '0.0274 (unconverged, 0.0253-0.0573)'; 'diverged'."""
        if self.diverged:
            return "diverged"
        s = f"{self.value:.{digits}g}"
        if not self.converged:
            s += f" (unconverged, {self.lo:.{digits}g}-{self.hi:.{digits}g})"
        return s


def less(a: Measured, b: Measured) -> Tri:
    """a < b, decided only if both converged and the margin exceeds both bands.

    A diverged b (and a finite a) counts as a decided 'a is better'; a diverged a as
    decided worse; both diverged: undecided.
    """
    if a.diverged or b.diverged:
        if a.diverged and b.diverged:
            return None
        if not (a.converged and b.converged):
            return None
        return b.diverged
    if not (a.converged and b.converged):
        return None
    if a.hi < b.lo:
        return True
    if a.lo > b.hi:
        return False
    return None  # the bands overlap: the margin lies within the convergence bands


def at_least(a: Measured, threshold: float) -> Tri:
    """a >= threshold, decided if a converged and its band lies on one side."""
    if a.diverged or not a.converged:
        return None
    if a.lo >= threshold:
        return True
    if a.hi < threshold:
        return False
    return None


def all3(values: Iterable[Tri]) -> Tri:
    """Three-valued AND: False if any is False, else None if any is None, else True."""
    vals = list(values)
    if any(v is False for v in vals):
        return False
    return None if any(v is None for v in vals) else True


def any3(values: Iterable[Tri]) -> Tri:
    """Three-valued OR: True if any is True, else None if any is None, else False."""
    vals = list(values)
    if any(v is True for v in vals):
        return True
    return None if any(v is None for v in vals) else False


def status_of(t: Tri) -> str:
    """'holds' | 'fails' | 'undecided'."""
    return UNDECIDED if t is None else (HOLDS if t else FAILS)


@dataclass(frozen=True)
class Verdict:
    """One claim: holds, fails or undecided in our model, the rule and the deciding numbers."""

    claim: str
    statement: str
    status: str
    rule: str
    evidence: str
    #: the comparisons decided against the claim, and those left undecided
    against: tuple[str, ...] = ()
    open: tuple[str, ...] = ()
    #: the same rule decided on each gait cycle alone (core/windows.py), on the paper's
    #: indices and on the stationary ones ('' where not decided so)
    windows: str = ""
    stationary: str = ""

    @property
    def holds(self) -> bool:
        """True only for a decided 'holds'."""
        return self.status == HOLDS


def total(parts: Sequence[Measured]) -> Measured:
    """Sum of numbers; its band is the sum of the bands (conservative)."""
    return Measured(sum(p.value for p in parts), sum(p.lo for p in parts),
                    sum(p.hi for p in parts), all(p.converged for p in parts))


def _ratio(a: Measured, b: Measured) -> Measured:
    """a / b with the band of the extreme ratios (both positive)."""
    if a.diverged or b.diverged:
        return Measured(math.inf if a.diverged else math.nan, math.nan, math.nan, False)
    return Measured(a.value / b.value, a.lo / b.hi, a.hi / b.lo, a.converged and b.converged)


Point = Mapping[str, Measured]  # index name -> measured value, for one case


def c1(pd_p: Point, pd_pf: Point, tracking: Sequence[str] = TRACKING) -> Verdict:
    """C1: base case, T_max 400: PD-P&F tracks hip and foot better and needs less torque.

    ``tracking``: the four tracking errors it is decided on (the paper's, or
    STATIONARY_TRACKING), here and in c2-c4."""
    names = tuple(tracking) + ("T_L",)
    cmp = {n: less(pd_pf[n], pd_p[n]) for n in names}
    ev = "; ".join(f"{n} {pd_pf[n].text()} vs {pd_p[n].text()} ({status_of(cmp[n])})"
                   for n in names)
    ev += f"; E_av {pd_pf['E_av'].text()} vs {pd_p['E_av'].text()}"
    return Verdict("C1", "Base, T_max 400: PD-P&F tracks hip and foot better than PD-P and "
                   "needs less joint torque", status_of(all3(cmp.values())),
                   "all four tracking errors and T_L of PD-P&F below PD-P's, each margin "
                   "beyond both dt-convergence bands", "PD-P&F vs PD-P: " + ev,
                   _listed(cmp, False, pd_pf, pd_p), _listed(cmp, None, pd_pf, pd_p))


def _listed(cmp: Mapping[str, Tri], want: Tri, a: Point, b: Point) -> tuple[str, ...]:
    return tuple(f"{n}: PD-P&F {a[n].text()} vs PD-P {b[n].text()}" for n, r in cmp.items()
                 if r is want)


def c2(sweeps: Mapping[float, Mapping[str, Sequence[Point]]], values: Sequence[float],
       tracking: Sequence[str] = TRACKING) -> Verdict:
    """C2: over the ground sweep at each T_max, PD-P&F's hip and foot errors below PD-P's.

    ``sweeps[t_max][controller][k]`` is the point at ground ``values[k]`` (a scale).
    """
    parts, results = [], []
    against: list[str] = []
    undecided: list[str] = []
    for t_max, by_c in sweeps.items():
        for n in tracking:
            cmp = [less(a[n], b[n]) for a, b in zip(by_c["pd_pf"], by_c["pd_p"])]
            results += cmp
            for v, r, a, b in zip(values, cmp, by_c["pd_pf"], by_c["pd_p"]):
                if r is not True:
                    (against if r is False else undecided).append(
                        f"{n} at {100 * v:.3g} %, T_max {t_max:g}: PD-P&F {a[n].text()} vs "
                        f"PD-P {b[n].text()}")
            lose = [f"{100 * v:.3g} %" for v, r in zip(values, cmp) if r is False]
            open_ = [f"{100 * v:.3g} %" for v, r in zip(values, cmp) if r is None]
            text = f"T_max {t_max:g}, {n}: below at {sum(r is True for r in cmp)}/{len(cmp)}"
            if lose:
                text += f"; above at {', '.join(lose)}"
            if open_:
                text += f"; undecided at {', '.join(open_)}"
            parts.append(text)
    return Verdict("C2", "Ground sweep at T_max 400 and 170: PD-P&F's hip and foot errors "
                   "stay below PD-P's over the whole range", status_of(all3(results)),
                   "every tracking error of PD-P&F below PD-P's at every ground percentage, "
                   "each margin beyond both dt-convergence bands", "; ".join(parts),
                   tuple(against), tuple(undecided))


def c3(strong: Mapping[str, Point], base: Mapping[str, Point], t_max: float,
       tracking: Sequence[str] = TRACKING) -> Verdict:
    """C3: T_max < 160: large degradation of the indices for both controllers."""
    ratios = {c: _ratio(total([strong[c][n] for n in tracking]),
                        total([base[c][n] for n in tracking])) for c in base}
    cmp = {c: (True if strong[c][tracking[0]].diverged and strong[c][tracking[0]].converged
               else at_least(r, C3_FACTOR)) for c, r in ratios.items()}
    x = tracking[0]
    ev = "; ".join(f"{c}: tracking errors x{r.text(3)} ({x} {strong[c][x].text()} "
                   f"vs {base[c][x].text()} m)" for c, r in ratios.items())
    return Verdict("C3", "T_max < 160: large degradation of the indices for both controllers",
                   status_of(all3(cmp.values())),
                   f"at T_max {t_max:g} the summed tracking errors are >= {C3_FACTOR:g}x "
                   "their T_max 400 value for both controllers (or the run diverges), over "
                   "the whole dt-convergence band", ev,
                   tuple(f"{c}: x{ratios[c].text(3)}" for c, r in cmp.items() if r is False),
                   tuple(f"{c}: x{ratios[c].text(3)}" for c, r in cmp.items() if r is None))


def c4(ideal: Mapping[float, Mapping[str, Point]],
       torque_step: Mapping[float, Mapping[str, Measured]],
       impact: Mapping[float, Mapping[str, Measured]] | None = None,
       tracking: Sequence[str] = TRACKING) -> Verdict:
    """C4: T_max -> inf: PD-P&F shows stability problems on ground harder than the base.

    ``ideal[scale][controller]`` are the points of a ground sweep at T_max = inf that
    includes scale 1.0; ``torque_step[scale][controller]`` the largest tick-to-tick torque
    change (N m) of that run. ``impact[scale][controller]``, if given, is the impact torque
    (hexapod_metrics.core.impacts: mean peak |T_m| within 20 ms after each touchdown, N m),
    a number with a continuous-time limit: it then decides the torque-impulse sign, and the
    torque step (whose samples' differences grow as dt shrinks) is only reported.
    """
    xh, yh = tracking[0], tracking[1]
    scales = sorted(ideal)
    hard = [s for s in scales if s > 1.0]
    base = ideal[min(scales, key=lambda s: abs(s - 1.0))]["pd_pf"]
    err_base = total([base[xh], base[yh]])
    diverged = [s for s in hard if ideal[s]["pd_pf"][xh].diverged]
    signs: list[Tri] = [True if ideal[s]["pd_pf"][xh].converged else None for s in diverged]
    growth = {s: _ratio(total([ideal[s]["pd_pf"][xh], ideal[s]["pd_pf"][yh]]),
                        err_base) for s in hard if s not in diverged}
    steps = {s: _ratio(torque_step[s]["pd_pf"], torque_step[s]["pd_p"]) for s in hard
             if s in torque_step}
    steps_text = ", ".join(f"x{r.text(3)} PD-P's at {100 * s:.3g} %" for s, r in steps.items())
    if impact is None:  # the torque step decides the torque-impulse sign
        deciding, name = steps, "torque step"
        rule = "its largest tick-to-tick torque step"
        tail = f"its largest torque step is {steps_text}"
    else:  # the impact torque decides; the torque step is only reported
        deciding = {s: _ratio(impact[s]["pd_pf"], impact[s]["pd_p"]) for s in hard
                    if s in impact}
        name = "impact torque"
        rule = "its impact torque (mean peak |T_m| within 20 ms after each touchdown)"
        tail = ("its impact torque (mean peak |T_m| within 20 ms after a touchdown) is "
                + ", ".join(f"x{r.text(3)} PD-P's at {100 * s:.3g} %"
                            for s, r in deciding.items())
                + f"; (not deciding) its largest tick-to-tick torque step is {steps_text}")
    signs += [at_least(g, C4_FACTOR) for g in growth.values()]
    signs += [at_least(r, C4_FACTOR) for r in deciding.values()]
    named = ([f"divergence at {100 * s:.3g} %" for s in diverged]
             + [f"hip error growth x{g.text(3)} at {100 * s:.3g} %" for s, g in growth.items()]
             + [f"{name} x{r.text(3)} PD-P's at {100 * s:.3g} %" for s, r in deciding.items()])
    ev = (f"PD-P&F diverged at {', '.join(f'{100 * s:.3g} %' for s in diverged) or 'no ground'}"
          "; its hip errors on hard ground reach "
          + ", ".join(f"x{g.text(3)} at {100 * s:.3g} %" for s, g in growth.items())
          + f" of the 100 % value; {tail}")
    return Verdict("C4", "T_max -> inf: PD-P&F shows stability problems (torque impulses at "
                   "foot impacts, growing errors) on ground harder than the base",
                   status_of(any3(signs)),
                   f"on ground > 100 % at T_max = inf, PD-P&F diverges, or its hip errors grow "
                   f">= {C4_FACTOR:g}x its 100 % value, or {rule} is >= {C4_FACTOR:g}x PD-P's, "
                   f"over the whole dt-convergence band", ev,
                   tuple(n for n, t in zip(named, signs) if t is False),
                   tuple(n for n, t in zip(named, signs) if t is None))


def point(conv: Convergence) -> dict[str, Measured]:
    """Every index of a checked case as :class:`Measured`."""
    return {n: Measured.of(conv, n) for n in REPORTED_NAMES}


__all__ = ["C3_FACTOR", "C4_FACTOR", "FAILS", "HOLDS", "Measured", "Point",
           "STATIONARY_TRACKING", "TRACKING", "UNDECIDED", "Verdict", "all3", "any3",
           "at_least", "c1", "c2", "c3", "c4", "total", "less", "point", "status_of"]
