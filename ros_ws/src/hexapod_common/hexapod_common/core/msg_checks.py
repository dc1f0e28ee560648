"""Checks every subscriber of the graph applies to what it receives, and the drop counts.

A message is *dropped* (never acted on, never recorded) for one of :data:`CAUSES`; each
drop is counted per topic and cause (:class:`DropCounter`), and the nodes report the counts
on ``/hexapod/status``, in their log and in their end summary. ROS-free: the nodes call
these after authentication (``msg_auth``) and decoding (``conversions``).
"""
from __future__ import annotations

import time
from math import isfinite
from typing import Callable, Iterable

import numpy as np

#: Why a message was dropped.
UNAUTHENTICATED = "unauthenticated"    # no valid tag: not from a node of this run
REPLAYED = "replayed"                  # a valid tag seen before
UNDECODABLE = "undecodable"            # not a serialized message of the topic's type
WRONG_SHAPE = "wrong names or sizes"   # decodes, but not the contract's joints and arrays
BAD_STAMP = "stamp outside the run"    # negative, not on a tick, ahead of the run or stale
NON_FINITE = "non-finite values"       # NaN or infinity in a value array
BAD_CONTENT = "unknown value"          # a string that is none of the allowed values
NEGATIVE_GAIN = "negative drive gain"  # a drive command's kp, kd or k_force below zero
CAUSES = (UNAUTHENTICATED, REPLAYED, UNDECODABLE, WRONG_SHAPE, BAD_STAMP, NON_FINITE,
          BAD_CONTENT, NEGATIVE_GAIN)

NS = 1_000_000_000
#: How far (simulated s) a message may be stamped ahead of the newest time a node knows ...
AHEAD_S = 1.0
#: ... plus this many simulated s per wall s since that time came (a node starved of CPU
#: for a while must still follow the run, whose clock went on: realtime runs at 1, lockstep
#: at its real-time factor).
RATE = 10.0


class Dropped(Exception):
    """A received message is not used; ``cause`` is one of :data:`CAUSES`."""

    def __init__(self, cause: str, detail: str = "") -> None:
        super().__init__(f"{cause}: {detail}" if detail else cause)
        self.cause = cause
        self.detail = detail


class DropCounter:
    """Dropped messages per (topic, cause)."""

    def __init__(self) -> None:
        self.counts: dict[tuple[str, str], int] = {}

    def add(self, topic: str, cause: str) -> int:
        """Count one drop; the new count of this (topic, cause)."""
        key = (topic, cause)
        n = self.counts.get(key, 0) + 1
        self.counts[key] = n
        return n

    @property
    def total(self) -> int:
        """All drops so far."""
        return sum(self.counts.values())

    def by_topic(self, topic: str) -> int:
        """Drops of one topic, every cause."""
        return sum(n for (t, _), n in self.counts.items() if t == topic)

    def values(self) -> dict[str, str]:
        """Diagnostic key/values: ``dropped`` (total) and ``dropped <topic> (<cause>)``."""
        out = {"dropped": str(self.total)}
        for (topic, cause), n in sorted(self.counts.items()):
            out[f"dropped {topic} ({cause})"] = str(n)
        return out

    def summary(self) -> str:
        """One phrase: 'no message dropped' or 'dropped N messages: topic n cause, ...'."""
        if not self.counts:
            return "no message dropped"
        parts = [f"{topic} {n} {cause}" for (topic, cause), n in sorted(self.counts.items())]
        return f"dropped {self.total} messages: " + ", ".join(parts)


def check_stamp(stamp_ns: int, period_ns: int) -> int:
    """The tick of a per-tick stamp; Dropped unless it is >= 0 and on a tick (to 1 ns)."""
    if stamp_ns < 0:
        raise Dropped(BAD_STAMP, f"negative stamp {stamp_ns} ns")
    k = (stamp_ns + period_ns // 2) // period_ns
    if abs(stamp_ns - k * period_ns) > 1:
        raise Dropped(BAD_STAMP, f"stamp {stamp_ns} ns is not on a control tick")
    return k


def check_drive_gains(position: np.ndarray, velocity: np.ndarray, effort: np.ndarray,
                      joints: int) -> None:
    """Dropped if a drive command's gains (the entries after the first ``joints``: kp in
    position, kd in velocity, k_force in effort; docs/controllers.md) are below zero."""
    for name, arr in (("kp", position), ("kd", velocity), ("k_force", effort)):
        gains = arr[joints:]
        if gains.size and gains.min() < 0.0:
            raise Dropped(NEGATIVE_GAIN, f"{name} = {float(gains.min()):g} (must be >= 0)")


def check_finite(arrays: Iterable[np.ndarray]) -> None:
    """Dropped if any value is NaN or infinite.

    ``math.isfinite`` over the values as Python floats: on the graph's 12-42-value arrays
    about a quarter of the time of ``np.isfinite(a).all()`` (two numpy calls and a
    temporary array each) here, and the graph checks 13 such messages a tick.
    """
    for a in arrays:
        if not all(map(isfinite, a.tolist())):
            raise Dropped(NON_FINITE)


class StampWindow:
    """The newest simulated time a node knows, and the stamps it accepts around it.

    ``advance(stamp)`` is for the node's time source (the sim's states): the first stamp is
    taken as it is, every later one must be at most ``ahead_s`` + ``rate`` x (wall s since
    the newest came) ahead of the newest (and, if ``increasing``, above it). ``check(stamp)``
    is for the other topics: within the same bound (before the first time source, within
    ``ahead_s`` of 0; the first time-source stamp itself is taken as it is).
    ``clock`` gives the wall time (s).
    """

    def __init__(self, ahead_s: float = AHEAD_S, increasing: bool = False,
                 rate: float = RATE, clock: Callable[[], float] = time.monotonic) -> None:
        self.ahead_ns = int(round(ahead_s * NS))
        self.increasing = increasing
        self.rate = rate
        self.clock = clock
        self.newest: int | None = None
        self.newest_wall = 0.0

    def check(self, stamp_ns: int) -> None:
        """Dropped if ``stamp_ns`` lies beyond the window."""
        if stamp_ns < 0:
            raise Dropped(BAD_STAMP, f"negative stamp {stamp_ns} ns")
        newest = 0 if self.newest is None else self.newest
        if stamp_ns > newest + self.ahead_ns:
            late = 0.0 if self.newest is None else (
                self.rate * (self.clock() - self.newest_wall) * NS)
            if stamp_ns > newest + self.ahead_ns + late:
                raise Dropped(BAD_STAMP, f"stamp {stamp_ns * 1e-9:.9g} s is ahead of the run "
                                         f"(now {newest * 1e-9:.9g} s)")

    def advance(self, stamp_ns: int) -> None:
        """Check a time-source stamp and make it the newest time (Dropped if it is not)."""
        if stamp_ns < 0:
            raise Dropped(BAD_STAMP, f"negative stamp {stamp_ns} ns")
        if self.newest is not None:
            self.check(stamp_ns)
        if self.increasing and self.newest is not None and stamp_ns <= self.newest:
            raise Dropped(BAD_STAMP, f"stamp {stamp_ns * 1e-9:.9g} s is not after "
                                     f"{self.newest * 1e-9:.9g} s")
        if self.newest is None or self.increasing or stamp_ns > self.newest:
            self.newest = stamp_ns
            self.newest_wall = self.clock()


__all__ = ["AHEAD_S", "RATE", "BAD_CONTENT", "NEGATIVE_GAIN",
           "BAD_STAMP", "CAUSES", "DropCounter", "Dropped",
           "NON_FINITE", "REPLAYED", "StampWindow", "UNAUTHENTICATED", "UNDECODABLE",
           "WRONG_SHAPE", "check_drive_gains", "check_finite", "check_stamp"]
