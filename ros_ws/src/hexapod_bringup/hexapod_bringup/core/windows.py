"""When is it measured: comparisons of two controllers cycle by cycle (E9, docs/indices.md).

A comparison of index ``name`` between controllers a and b is the sign of b - a in each gait
cycle. It *settles* at cycle k when its sign is the same in every cycle from k to the last
one scored; a claim decided on that index holds (or fails) whatever the window only if it
settles at or before :data:`FIRST_WINDOW` (the second full cycle: cycle 0 is the start from
rest). An index is *stationary* when cycle 10 and cycle 20 agree within the dt-convergence
tolerance (1 %, or 1 mm for lengths; convergence.tolerance).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

from hexapod_metrics.core.indices import DRIFT_NAMES, INDEX_NAMES, Indices

from .claims import Verdict
from .convergence import tolerance

#: The first cycle a verdict is read at (cycle 0 starts from rest).
FIRST_WINDOW = 1
#: The indices E9 follows: the paper's seven and the window-independent four.
FOLLOWED = INDEX_NAMES + DRIFT_NAMES
#: The cycles compared to call an index stationary.
STATIONARY_CYCLES = (10, 20)
#: The last window a claim is decided at (issue: from the second full cycle to the 20th).
LAST_WINDOW = 20
#: A claim whose verdict is not the same in every window.
DEPENDS = "depends on the window"


@dataclass(frozen=True)
class Settling:
    """How the sign of b - a of one index goes over the cycles."""

    signs: tuple[int, ...]
    """sign(b - a) per cycle (0: equal or not a number in either)."""
    from_cycle: int | None
    """The first cycle from which the sign never changes again (None: no cycle scored)."""

    @property
    def final(self) -> int:
        """The sign the comparison settles on."""
        return self.signs[-1] if self.signs else 0

    def window_dependent(self, first: int = FIRST_WINDOW) -> bool:
        """True if the sign changes after cycle ``first`` (the verdict depends on the window)."""
        return self.from_cycle is None or self.from_cycle > first

    def describe(self, a: str, b: str, first: int = FIRST_WINDOW) -> str:
        """'B lower in every cycle from 1' or 'depends on the window: A lower in cycles 1-2,
        B lower from cycle 3' (``a``, ``b``: the two controllers' names)."""
        who = {-1: f"{b} lower", 1: f"{a} lower", 0: "equal"}
        if self.from_cycle is None:
            return "not scored"
        if not self.window_dependent(first):
            return f"{who[self.final]} in every cycle from {first}"
        before = self.signs[self.from_cycle - 1]
        return (f"depends on the window: {who[before]} in cycles {first}-"
                f"{self.from_cycle - 1}, {who[self.final]} from cycle {self.from_cycle}")


def _sign(x: float) -> int:
    return 0 if not math.isfinite(x) or x == 0 else (1 if x > 0 else -1)


def settling(a: Sequence[Indices | None], b: Sequence[Indices | None], name: str,
             first: int = FIRST_WINDOW) -> Settling:
    """The sign of b - a of index ``name`` per cycle from ``first`` on, and where it settles
    (a cycle either run did not walk counts as sign 0)."""
    signs = tuple(_sign(getattr(y, name) - getattr(x, name)) if x and y else 0
                  for x, y in zip(a[first:], b[first:]))
    if not signs:
        return Settling((), None)
    k = len(signs) - 1
    while k > 0 and signs[k - 1] == signs[-1]:
        k -= 1
    return Settling(tuple([0] * first) + signs, first + k)


def stationary(cycles: Sequence[Indices | None], name: str,
               at: tuple[int, int] = STATIONARY_CYCLES) -> bool:
    """Index ``name`` agrees between the two cycles ``at`` within its dt tolerance."""
    if len(cycles) <= max(at):
        return False
    x, y = cycles[at[0]], cycles[at[1]]
    if x is None or y is None:
        return False
    u, v = getattr(x, name), getattr(y, name)
    return bool(abs(u - v) < tolerance(name, v))


@dataclass(frozen=True)
class WindowVerdict:
    """A claim decided on each gait cycle alone, from cycle ``first`` on."""

    claim: str
    statuses: tuple[str, ...]
    """holds / fails / undecided (claims.py) in cycles first, first + 1, ..."""
    first: int = FIRST_WINDOW
    verdicts: tuple[Verdict, ...] = ()

    @property
    def status(self) -> str:
        """The verdict if it is the same in every window, else :data:`DEPENDS`."""
        return self.statuses[0] if len(set(self.statuses)) == 1 else DEPENDS

    def text(self) -> str:
        """'holds in every window (cycles 1-20)' or 'depends on the window: fails in cycles
        1-2, undecided in cycle 3, holds from cycle 4'."""
        last = self.first + len(self.statuses) - 1
        if self.status != DEPENDS:
            return f"{self.status} in every window (cycles {self.first}-{last})"
        runs: list[tuple[str, int, int]] = []
        for k, st in enumerate(self.statuses, start=self.first):
            if runs and runs[-1][0] == st:
                runs[-1] = (st, runs[-1][1], k)
            else:
                runs.append((st, k, k))
        parts = []
        for j, (st, a, b) in enumerate(runs):
            if j == len(runs) - 1 and b == last and a > self.first:
                parts.append(f"{st} from cycle {a}")
            else:
                parts.append(f"{st} in cycle{'s' if b > a else ''} "
                             f"{a}{f'-{b}' if b > a else ''}")
        return f"{DEPENDS}: " + ", ".join(parts)


def decided_over_windows(name: str, decide: Callable[[int], str], first: int = FIRST_WINDOW,
                         last: int = LAST_WINDOW) -> WindowVerdict:
    """Any verdict (``decide(k)``: its word on gait cycle k alone, e.g. 'pd_pf better')
    decided on each of the cycles ``first``..``last``; ``name`` labels it."""
    return WindowVerdict(name, tuple(decide(k) for k in range(first, last + 1)), first)


def over_windows(decide: Callable[[int], Verdict], first: int = FIRST_WINDOW,
                 last: int = LAST_WINDOW) -> WindowVerdict:
    """Decide a claim on each of the gait cycles ``first``..``last`` alone
    (``decide(k)``: the claim's verdict on cycle k's indices)."""
    verdicts = tuple(decide(k) for k in range(first, last + 1))
    return WindowVerdict(verdicts[0].claim, tuple(v.status for v in verdicts), first, verdicts)


__all__ = ["DEPENDS", "FIRST_WINDOW", "FOLLOWED", "LAST_WINDOW", "STATIONARY_CYCLES",
           "Settling", "WindowVerdict", "decided_over_windows", "over_windows", "settling",
           "stationary"]
