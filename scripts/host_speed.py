"""How fast this shared, virtual machine runs plain Python right now.

The benchmarks print :func:`describe` before and after their figures: on these machines the
same code ran 1.5x slower within one hour (no steal time shown to the guest), so a figure is
only comparable with another measured at a similar host speed.
"""
from __future__ import annotations

import statistics
import time

STEPS = 1_000_000


def loop_ms(repeats: int = 5) -> float:
    """Median wall ms of a ``STEPS``-step pure-Python loop (multiply and add)."""
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        s = 0
        for i in range(STEPS):
            s += i * i
        times.append(time.perf_counter() - t)
    return 1e3 * statistics.median(times)


def describe() -> str:
    """One phrase: the loop's time now."""
    return f"host speed: a {STEPS:,}-step Python loop takes {loop_ms():.0f} ms"


__all__ = ["STEPS", "describe", "loop_ms"]
