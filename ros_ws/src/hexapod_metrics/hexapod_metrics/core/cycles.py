"""The one gait-cycle scorer: the metrics node, ``hexapod analyze`` and ``simulate --bag``.

Samples of the four state topics (:data:`CYCLE_TOPICS`) come in per tick, as serialized
JointStates (the node, ``simulate --bag``) or as decoded blocks (the bag reader); the
controller labels come from joint_states' frame_id (``hexapod_common.core.labels``). Gait
cycle c spans ticks k_a = c M .. k_b = (c + 1) M (M = T / Delta t) and is scored
(:func:`~.indices.sums_from_obs`, samples 1..M, as the engine) once every topic has
reached k_b (a tick missing in it: the cycle has no sums), or, live, once a topic is far past
it while another has not reached it (a dead topic). The
first cycle is the first one that starts at or after the first tick seen. Memory: about one
cycle of samples.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from hexapod_common.core import labels as L
from hexapod_common.core import topics as T

from hexapod_common.core.cdr import decode_joint_state_batch
from .indices import (REPORTED_NAMES, Indices, WindowSums, lag_growth, per_cycle_mean,
                      sums_from_obs)

#: The state topics a cycle's indices need, all stamped per tick.
CYCLE_TOPICS = (T.JOINT_STATES, T.FOOT_FORCES, T.HIP_STATES, T.REFERENCE)

IntArray = npt.NDArray[np.int64]
FloatArray = npt.NDArray[np.float64]
SampleHook = Callable[[int, int, FloatArray, dict[str, FloatArray]], None]


@dataclass(frozen=True)
class Cycle:
    """Gait cycle ``cycle`` (ticks cycle*M .. (cycle+1)*M): who ran it and its sums.

    ``controller``: the label (``labels.cycle_label``: the controller only if it commanded
    every torque of the cycle); ``in_charge``: the controller(s) in charge (``a->b``)."""

    cycle: int
    t_a: float
    t_b: float
    controller: str
    in_charge: str
    uncommanded: int
    sums: WindowSums | None    # None if ticks are missing
    missing: int = 0
    lag_growth: float = float("nan")
    fallen: str = ""
    """Why the cycle was not a walk (walking.not_walking; "" if it was one)."""

    @property
    def indices(self) -> Indices | None:
        """The cycle's indices, None if incomplete or not a walk."""
        return self.sums.indices() if self.sums and not self.fallen else None

    def as_dict(self) -> dict[str, Any]:
        """The cycle as indices.json lists it (only for cycles with sums); a cycle that was
        not a walk has ``fallen`` (why) and no indices."""
        idx = self.indices
        return {"cycle": self.cycle, "t_a": self.t_a, "t_b": self.t_b,
                "controller": self.in_charge, "label": self.controller,
                "uncommanded_ticks": self.uncommanded,
                "indices": idx.as_dict() if idx else None, "lag_growth": self.lag_growth,
                **({"fallen": self.fallen} if self.fallen else {})}


class TickLabels:
    """Controller in charge and torque source per tick, from joint_states frame_ids.

    Kept as change points; :meth:`at` looks ticks up vectorised."""

    def __init__(self) -> None:
        self.controllers: list[tuple[int, str]] = []  # (tick, controller) at each change
        self.sources: list[tuple[int, str]] = []      # (torque tick, source) at each change
        self.history: list[tuple[int, str]] = []
        """(first tick, controller in charge) of every stretch seen (never pruned)."""
        self._frame: str | None = None

    def add(self, tick: int, frame_id: str) -> None:
        """The frame_id of the joint_states of ``tick`` (ticks in increasing order)."""
        if frame_id == self._frame:
            return
        self._frame = frame_id
        controller, source = L.parse_state_frame(frame_id)
        if not self.history or self.history[-1][1] != controller:
            self.controllers.append((tick, controller))
            self.history.append((tick, controller))
        if tick > 0 and (self.sources[-1][1] if self.sources else L.COMMANDED) != source:
            self.sources.append((tick - 1, source))  # sample k carries the torque of k-1

    def at(self, ticks: npt.ArrayLike) -> tuple[npt.NDArray[Any], npt.NDArray[Any]]:
        """(controllers, sources) of ``ticks``."""
        return (_lookup(self.controllers, ticks, L.UNKNOWN),
                _lookup(self.sources, ticks, L.COMMANDED))

    def drop_before(self, tick: int) -> None:
        """Forget changes that no tick >= ``tick`` needs."""
        for changes in (self.controllers, self.sources):
            i = int(np.searchsorted([k for k, _ in changes], tick, side="right")) - 1
            if i > 0:
                del changes[:i]


def _lookup(changes: list[tuple[int, str]], ticks: npt.ArrayLike,
            default: str) -> npt.NDArray[Any]:
    starts = np.array([k for k, _ in changes], dtype=np.int64)
    names = np.array([default] + [c for _, c in changes], dtype=object)
    return names[np.searchsorted(starts, np.asarray(ticks), side="right")]


class _Buffer:
    """Rows (position, velocity, effort) of one topic not yet consumed, keyed by tick."""

    def __init__(self) -> None:
        self.k: IntArray = np.zeros(0, np.int64)
        self.data: FloatArray | None = None  # (n, 3, width)
        self.blocks: list[tuple[IntArray, FloatArray]] = []
        self.raw: list[bytes] = []
        self.raw_k: list[int] = []
        self.last = -1
        self.first = -1

    def push(self, k: IntArray, pos: FloatArray, vel: FloatArray, eff: FloatArray) -> None:
        if len(k):
            self._flush_raw()
            self.blocks.append((k, np.stack([pos, vel, eff], axis=1)))
            self._seen(int(k.min()), int(k.max()))

    def push_raw(self, k: int, data: bytes) -> None:
        self.raw.append(data)
        self.raw_k.append(k)
        self._seen(k, k)

    def _seen(self, lo: int, hi: int) -> None:
        self.last = max(self.last, hi)
        self.first = lo if self.first < 0 else min(self.first, lo)

    def _flush_raw(self) -> None:
        if self.raw:
            a = decode_joint_state_batch(self.raw)
            self.blocks.append((np.array(self.raw_k, np.int64),
                                np.stack([a.position, a.velocity, a.effort], axis=1)))
            self.raw, self.raw_k = [], []

    def _consolidate(self) -> None:
        self._flush_raw()
        if not self.blocks:
            return
        ks = [self.k] + [k for k, _ in self.blocks]
        rows = ([] if self.data is None else [self.data]) + [d for _, d in self.blocks]
        self.blocks = []
        k = np.concatenate(ks)
        data = np.concatenate(rows)
        if not bool(np.all(np.diff(k) > 0)):  # out of order or duplicated: sort, keep first
            k, first = np.unique(k, return_index=True)
            data = data[first]
        self.k, self.data = k, data

    def window(self, k0: int, k1: int) -> tuple[IntArray, FloatArray]:
        """Ticks present in [k0, k1] and their rows."""
        self._consolidate()
        a, b = np.searchsorted(self.k, [k0, k1 + 1])
        assert self.data is not None
        return self.k[a:b], self.data[a:b]

    def drop_before(self, k: int) -> None:
        self._consolidate()
        a = int(np.searchsorted(self.k, k))
        self.k = self.k[a:]
        if self.data is not None:
            self.data = self.data[a:]


class CycleScorer:
    """Scores each full gait cycle of a run from its per-tick samples (see the module doc).

    Feed samples (:meth:`add_raw` per message or :meth:`add_block`) and joint_states frame
    ids (:meth:`add_frame`, in tick order), then :meth:`take` the cycles that became
    complete; ``take(final=True)`` at the end also scores the cycles cut short."""

    def __init__(self, ticks_per_cycle: int, period: float, gap_ticks: int | None = None,
                 on_samples: SampleHook | None = None,
                 walk: Callable[[WindowSums], str | None] | None = None) -> None:
        """``gap_ticks``: give a cycle up (no sums) once a topic is this many ticks past its
        end while another has not reached it (live runs; None: wait, as for a bag, whose
        topics come chunk by chunk). ``on_samples(k0, k1, obs, ref)``: called with each
        complete cycle's samples (obs (M+1, 9, 6, 2), ref: ``topics.split_reference``).
        ``walk(sums)``: why a cycle was not a walk, None if it was (walking.not_walking)."""
        self.walk = walk
        self.gap = gap_ticks
        self.on_samples = on_samples
        self.n = int(ticks_per_cycle)
        self.period = float(period)
        self.labels = TickLabels()
        self.buffers = {t: _Buffer() for t in CYCLE_TOPICS}
        self.next_cycle: int | None = None
        self.cycles: list[Cycle] = []
        """Every cycle taken so far."""

    @property
    def latest(self) -> int:
        """The newest tick seen on any topic (-1 before the first)."""
        return max(b.last for b in self.buffers.values())

    @property
    def last_state(self) -> int:
        """The newest joint_states tick seen (-1 before the first)."""
        return self.buffers[T.JOINT_STATES].last

    def add_raw(self, topic: str, tick: int, data: bytes) -> None:
        """One serialized JointState of ``topic`` at ``tick``; one before the cycle being
        scored is ignored."""
        if self.next_cycle is not None and tick < self.next_cycle * self.n:
            return
        self.buffers[topic].push_raw(tick, data)

    def add_block(self, topic: str, ticks: IntArray, position: FloatArray,
                  velocity: FloatArray, effort: FloatArray) -> None:
        """Decoded samples (rows of ticks) of ``topic``."""
        self.buffers[topic].push(ticks, position, velocity, effort)

    def add_frame(self, tick: int, frame_id: str) -> None:
        """The joint_states frame_id of ``tick`` (every tick, or only where it changes)."""
        self.labels.add(tick, frame_id)

    def take(self, final: bool = False) -> list[Cycle]:
        """The cycles that became complete since the last call, in order."""
        bufs = self.buffers.values()
        if self.next_cycle is None:
            seen = [b for b in bufs if b.last >= 0]
            if not seen or (len(seen) < len(bufs) and not self._gap(
                    max(b.last for b in seen), min(b.first for b in seen) + self.n)):
                return []
            first = min(b.first for b in seen)
            self.next_cycle = -(-first // self.n)  # the first boundary at or after it
        out: list[Cycle] = []
        while True:
            c = self.next_cycle
            k1 = (c + 1) * self.n
            lo, hi = min(b.last for b in bufs), max(b.last for b in bufs)
            if not (lo >= k1 or self._gap(hi, k1) or (final and hi >= k1)):
                break
            cycle = self._score(c)
            out.append(cycle)
            self.cycles.append(cycle)
            self.next_cycle = c + 1
            for b in bufs:
                b.drop_before(k1)
            self.labels.drop_before(k1)
        return out

    def _gap(self, newest: int, end: int) -> bool:
        return self.gap is not None and newest > end + self.gap

    def _score(self, c: int) -> Cycle:
        k0, k1 = c * self.n, (c + 1) * self.n
        dt = self.period
        controllers, sources = self.labels.at(np.arange(k0, k1))
        label, who, uncommanded = L.cycle_label(list(controllers), list(sources))
        parts = {t: b.window(k0, k1) for t, b in self.buffers.items()}
        lost = max(k1 - k0 + 1 - len(ks) for ks, _ in parts.values())
        if lost:
            return Cycle(c, k0 * dt, k1 * dt, label, who, uncommanded, None, lost)
        cols = {t: (rows[:, 0], rows[:, 1], rows[:, 2]) for t, (_, rows) in parts.items()
                if t != T.REFERENCE}
        obs = T.obs_from_columns(cols)
        ref_rows = parts[T.REFERENCE][1]
        ref = T.split_reference(ref_rows[:, 0], ref_rows[:, 1])
        sums = sums_from_obs(obs, ref["hip"], ref["foot"], dt)
        if self.on_samples is not None:
            self.on_samples(k0, k1, obs, ref)
        fallen = (self.walk(sums) if self.walk is not None else None) or ""
        prev = self.cycles[-1] if self.cycles else None
        growth = (lag_growth(prev.indices, sums.indices())
                  if prev is not None and prev.cycle == c - 1 and not fallen
                  else float("nan"))
        return Cycle(c, k0 * dt, k1 * dt, label, who, uncommanded, sums, 0, growth, fallen)

def indices_values(cycle: Cycle) -> tuple[tuple[str, str], ...]:
    """The key/values of a cycle's /hexapod/indices status (its indices, L, lag, growth,
    label, controllers in charge, uncommanded ticks, cycle and times; a cycle that was not a
    walk: ``fallen`` and why, no indices)."""
    idx = cycle.indices
    if cycle.fallen:
        values: tuple[tuple[str, str], ...] = (("fallen", cycle.fallen),)
    else:
        assert idx is not None
        values = tuple((n, repr(float(getattr(idx, n)))) for n in REPORTED_NAMES)
        values += (("lag_growth", repr(float(cycle.lag_growth))),)
    return values + (("controller", cycle.controller), ("in_charge", cycle.in_charge),
                     ("uncommanded_ticks", str(cycle.uncommanded)), ("cycle", str(cycle.cycle)),
                     ("t_a", repr(cycle.t_a)), ("t_b", repr(cycle.t_b)))


def segments(cycles: Sequence[Cycle], changes: Sequence[tuple[int, str]], period: float,
             last_tick: int) -> list[dict[str, Any]]:
    """Per stretch of one controller in charge (``changes``: (first tick, controller)), its
    full cycles and the last of them (each with its label: ``fallback``, ``mixed(...)`` if
    the controller did not command all of it), and the segment's indices: the per-cycle
    mean over the cycles the controller commanded entirely (``mean_cycles``; model.md: not
    the index of their union), None if it has none or one of them was not a walk
    (``fallen`` then says which and why)."""
    out = []
    for i, (k, who) in enumerate(changes):
        end = changes[i + 1][0] if i + 1 < len(changes) else last_tick
        mine = [c for c in cycles if c.in_charge == who and c.sums is not None
                and k * period <= c.t_a + 1e-9 and c.t_b <= max(end, k) * period + 1e-9]
        own = [c for c in mine if c.controller == who]
        fell = next((f"cycle {c.cycle}: {c.fallen}" for c in own if c.fallen), "")
        scored = [c.indices for c in own if c.indices is not None]
        mean = per_cycle_mean(scored).as_dict() if scored and not fell else None
        out.append({"controller": who, "from_tick": k,
                    "to_tick": end - 1 if i + 1 < len(changes) else last_tick,
                    "t_start": k * period,
                    "t_end": end * period, "cycles": [c.cycle for c in mine],
                    "mean_cycles": [c.cycle for c in own], "per_cycle_mean": mean,
                    **({"fallen": fell} if fell else {}),
                    "last_full_cycle": mine[-1].as_dict() if mine else None})
    return out


__all__ = ["CYCLE_TOPICS", "Cycle", "CycleScorer", "TickLabels", "indices_values", "segments"]
