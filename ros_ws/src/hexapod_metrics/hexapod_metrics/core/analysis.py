"""Offline analysis of a bag: the seven indices per gait cycle and per controller segment.

The bag is streamed chunk by chunk: samples are kept only until the gait cycle they belong to
is complete, then reduced to additive :class:`~.indices.WindowSums`, so memory is bounded by
one cycle (plus decimated plot series), not by the bag. The sample convention is the
engine's (indices.py), so the analysis of a graph bag equals the engine's and the metrics
node's numbers.

Which controller was in charge at each tick comes from the ``header.frame_id`` of
``/hexapod/joint_states`` (the sim writes the controller's name there); segments are split at
its changes, i.e. at the recorded switches, and at every recorded parameter change
(bag_params.py), each segment naming the values that differ from the start.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from hexapod_sim.core import topics as T
from hexapod_sim.core.cdr import decode_diagnostic_array
from hexapod_sim.core.errors import CdrError
from hexapod_sim.core.layout import O_HP, O_TQ
from hexapod_sim.core.param_log import ParamTimeline
from hexapod_sim.core.params import HexapodParams

from ..bag import Bag, BagReadError, iter_joint_state_blocks, open_bag
from .bag_params import bag_params
from .indices import Indices, WindowSums, sums_from_obs
from .recording import status_indices

STREAMS = (T.JOINT_STATES, T.FOOT_FORCES, T.HIP_STATES, T.REFERENCE)
#: At most this many points per plot series (older points are thinned by 2 when exceeded).
MAX_PLOT_POINTS = 20000
MIXED = "mixed"


@dataclass(frozen=True)
class CycleResult:
    """Gait cycle ``cycle`` (ticks cycle*M .. (cycle+1)*M): who ran it and its indices."""

    cycle: int
    t_a: float
    t_b: float
    controller: str            # MIXED if a switch happened inside the cycle
    sums: WindowSums | None    # None if ticks are missing
    missing: int = 0

    @property
    def indices(self) -> Indices | None:
        """The cycle's indices, None if incomplete."""
        return self.sums.indices() if self.sums else None


@dataclass(frozen=True)
class SegmentResult:
    """A stretch of the run under one controller and the indices of its complete cycles."""

    controller: str
    t_start: float
    t_end: float
    cycles: int
    indices: Indices | None
    params: tuple[tuple[str, Any], ...] = ()
    """Parameters in force over the segment that differ from the start values."""


@dataclass
class PlotSeries:
    """Decimated time series of leg 1 for the figures: t, |dxH|, |dyH|, T_m11, T_m12, label."""

    stride: int = 1
    t: list[np.ndarray] = field(default_factory=list)
    values: list[np.ndarray] = field(default_factory=list)  # (n, 4)
    labels: list[np.ndarray] = field(default_factory=list)

    def add(self, t: np.ndarray, values: np.ndarray, labels: np.ndarray) -> None:
        """Append samples (already thinned by ``stride``)."""
        self.t.append(t)
        self.values.append(values)
        self.labels.append(labels)
        if sum(len(a) for a in self.t) > MAX_PLOT_POINTS:
            self.t, self.values, self.labels = ([np.concatenate(x)[::2]] for x in (
                self.t, self.values, self.labels))
            self.stride *= 2

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(t, values (n, 4), labels)."""
        if not self.t:
            return np.zeros(0), np.zeros((0, 4)), np.zeros(0, dtype=object)
        return (np.concatenate(self.t), np.concatenate(self.values),
                np.concatenate(self.labels))


@dataclass
class BagAnalysis:
    """Everything ``hexapod analyze`` reports about one bag."""

    path: Path
    params: HexapodParams
    params_source: str
    truncated: bool
    truncation_reason: str
    ticks: int
    cycles: list[CycleResult]
    segments: list[SegmentResult]
    switches: list[tuple[float, str]]
    online: list[tuple[int, str, Indices]]
    series: PlotSeries
    param_changes: list[tuple[float, str, str, Any]] = field(default_factory=list)
    """(time s, node, name, value) of every recorded parameter change, applied there."""


def controller_changes(bag: Bag, dt_ns: int,
                       online: list[tuple[int, str, Indices]] | None = None
                       ) -> list[tuple[int, str]]:
    """(first tick, controller) at the start and at every change of joint_states' frame_id.

    If ``online`` is given, the bag's /hexapod/indices records are appended to it as
    (cycle, controller, indices).
    """
    if online is not None:
        online.extend(online_indices(bag))
    frames: dict[str, list[tuple[int, str]]] = {T.JOINT_STATES: []}
    for _ in iter_joint_state_blocks(bag, [T.JOINT_STATES], frames=frames):
        pass
    return ticks_of_changes(frames[T.JOINT_STATES], dt_ns)


def ticks_of_changes(frames: list[tuple[int, str]], dt_ns: int) -> list[tuple[int, str]]:
    """(stamp ns, frame_id) changes -> (tick, controller); an empty frame_id is 'unknown'."""
    return [(int(round(stamp / dt_ns)), frame or "unknown") for stamp, frame in frames]


def online_indices(bag: Bag) -> list[tuple[int, str, Indices]]:
    """The per-cycle indices the recorder published (/hexapod/indices), in file order."""
    if T.INDICES not in bag.topics:
        return []
    return [r for _, _, raw in bag.messages([T.INDICES]) for r in _online_records(raw)]


def label_ticks(changes: list[tuple[int, str]], ticks: np.ndarray) -> np.ndarray:
    starts = np.array([k for k, _ in changes], dtype=np.int64)
    names = np.array([c for _, c in changes] or ["unknown"], dtype=object)
    pos = np.searchsorted(starts, ticks, side="right") - 1
    return names[np.clip(pos, 0, None)]


class _Buffer:
    """Rows of one topic not yet consumed, keyed by tick: one growable (n, 3, width) array
    whose live rows are ``[a, b)``, so a push copies only the new rows."""

    def __init__(self) -> None:
        self._k = np.zeros(0, np.int64)
        self._data = np.zeros((0, 3, 0))
        self._a = self._b = 0

    @property
    def k(self) -> np.ndarray:
        """Ticks of the live rows, ascending."""
        return self._k[self._a:self._b]

    def _room(self, n: int, width: int) -> None:
        live = self._b - self._a
        if self._b + n <= len(self._k) and self._data.shape[2] == width:
            return
        cap = max(2 * (live + n), 4096) if live + n > len(self._k) // 2 else len(self._k)
        k = np.empty(cap, np.int64)
        data = np.empty((cap, 3, width))
        if live:  # (a topic's width never changes: the decoder refuses other names)
            k[:live] = self._k[self._a:self._b]
            data[:live] = self._data[self._a:self._b]
        self._k, self._data, self._a, self._b = k, data, 0, live

    def push(self, k: np.ndarray, pos: np.ndarray, vel: np.ndarray, eff: np.ndarray) -> None:
        n = len(k)
        if n == 0:
            return
        self._room(n, pos.shape[1])
        a, b = self._a, self._b
        # the new ticks must follow the old ones (checked at the seam)
        ordered = (b == a or int(k[0]) > int(self._k[b - 1])) and bool(np.all(np.diff(k) > 0))
        self._k[b:b + n] = k
        rows = self._data[b:b + n]
        rows[:, 0], rows[:, 1], rows[:, 2] = pos, vel, eff
        self._b = b + n
        if not ordered:  # out of order or duplicated: sort, keep the first
            ks, first = np.unique(self._k[a:self._b], return_index=True)
            self._data[a:a + len(ks)] = self._data[a:self._b][first]
            self._k[a:a + len(ks)] = ks
            self._b = a + len(ks)

    def window(self, k0: int, k1: int) -> tuple[np.ndarray, np.ndarray]:
        """Ticks present in [k0, k1] and their rows (views, valid until the next push)."""
        i, j = np.searchsorted(self.k, [k0, k1 + 1])
        return self.k[i:j], self._data[self._a + i:self._a + j]

    def drop_before(self, k: int) -> None:
        self._a += int(np.searchsorted(self.k, k))

    @property
    def last(self) -> int:
        return int(self._k[self._b - 1]) if self._b > self._a else -1


def _online_records(raw: bytes) -> list[tuple[int, str, Indices]]:
    """The per-cycle indices of one /hexapod/indices message."""
    out = []
    try:
        statuses = decode_diagnostic_array(raw)[1]
    except CdrError as err:
        raise BagReadError(f"{T.INDICES}: {err}") from err
    for st in statuses:
        try:
            idx, kv = status_indices(st)
        except (KeyError, ValueError):
            continue
        out.append((int(kv.get("cycle", -1)), kv.get("controller", "?"), idx))
    return out


def analyze_bag(path: str | Path) -> BagAnalysis:
    """Stream a bag of this project and compute per-cycle and per-segment indices."""
    with open_bag(path) as bag:
        missing = [t for t in STREAMS if t not in bag.topics]
        if missing:
            raise BagReadError(f"{path}: not a hexapod bag (no {', '.join(missing)})")
        p, source, tl, _ = bag_params(bag)
        dt = p.sim.control_period
        dt_ns = int(round(dt * 1e9))
        m = int(round(p.cycle_time / dt))
        indices_raw: dict[str, list[tuple[int, bytes]]] = {T.INDICES: []}  # same pass
        # controller changes (joint_states' frame_id, found vectorised in the same pass as
        # the decoding) and, among them, a boundary at every parameter change
        frames: dict[str, list[tuple[int, str]]] = {T.JOINT_STATES: []}
        switch_ticks: list[tuple[int, str]] = []
        changes: list[tuple[int, str]] = []
        buffers = {t: _Buffer() for t in STREAMS}
        series = PlotSeries(stride=max(1, bag.topics[T.JOINT_STATES].message_count
                                       // MAX_PLOT_POINTS))
        cycles: list[CycleResult] = []
        first_tick: int | None = None
        next_cycle: int | None = None
        ticks = 0
        last_tick = 0

        def consume(final: bool) -> None:
            nonlocal next_cycle
            while next_cycle is not None:
                k0, k1 = next_cycle * m, (next_cycle + 1) * m
                if not final and min(b.last for b in buffers.values()) < k1:
                    return
                if final and max(b.last for b in buffers.values()) < k1:
                    return
                cycles.append(_cycle(next_cycle, k0, k1))
                for b in buffers.values():
                    b.drop_before(k1)
                next_cycle += 1

        def _cycle(c: int, k0: int, k1: int) -> CycleResult:
            parts = {t: buffers[t].window(k0, k1) for t in STREAMS}
            want = k1 - k0 + 1
            lost = max(want - len(ks) for ks, _ in parts.values())
            labels = label_ticks(changes, np.arange(k0, k1))  # who computed the torques
            who = labels[0] if np.all(labels == labels[0]) else MIXED
            if lost:
                return CycleResult(c, k0 * dt, k1 * dt, who, None, lost)
            cols = {t: (rows[:, 0], rows[:, 1], rows[:, 2]) for t, (_, rows) in parts.items()
                    if t != T.REFERENCE}
            obs = T.obs_from_columns(cols)
            ref_rows = parts[T.REFERENCE][1]
            ref = T.split_reference(ref_rows[:, 0], ref_rows[:, 1])
            sel = slice(0, want - 1, series.stride)  # ticks k0 .. k1-1
            sig = np.stack([np.abs(ref["hip"][sel, 0, 0] - obs[sel, O_HP, 0, 0]),
                            np.abs(ref["hip"][sel, 0, 1] - obs[sel, O_HP, 0, 1]),
                            obs[sel, O_TQ, 0, 0], obs[sel, O_TQ, 0, 1]], axis=1)
            ks = np.arange(k0, k1)[sel]
            series.add(ks * dt, sig, label_ticks(changes, ks))
            return CycleResult(c, k0 * dt, k1 * dt, who,
                               sums_from_obs(obs, ref["hip"], ref["foot"], dt))

        for topic, arrays in iter_joint_state_blocks(bag, STREAMS, frames=frames,
                                                     others=indices_raw):
            if frames[T.JOINT_STATES]:  # labels of ticks up to the newest state are final
                switch_ticks += ticks_of_changes(frames[T.JOINT_STATES], dt_ns)
                frames[T.JOINT_STATES].clear()
                changes = (with_param_boundaries(switch_ticks, tl) if tl is not None
                           else list(switch_ticks))
            k = np.rint(arrays.stamps / dt_ns).astype(np.int64)
            buffers[topic].push(k, arrays.position, arrays.velocity, arrays.effort)
            if topic == T.JOINT_STATES:
                ticks += len(k)
                last_tick = max(last_tick, int(k.max(initial=-1)))
            if first_tick is None and min(b.last for b in buffers.values()) >= 0:
                first_tick = int(min(b.k[0] for b in buffers.values()))
                next_cycle = -(-first_tick // m)  # first cycle boundary at or after it
            consume(final=False)
        consume(final=True)
        online = [r for _, raw in indices_raw[T.INDICES] for r in _online_records(raw)]
        truncated, reason = bag.truncated, bag.truncation_reason
    if ticks == 0:
        why = f" (truncated: {reason})" if truncated else ""
        raise BagReadError(f"{path}: no hexapod samples in the readable part of the bag{why}")
    segments = _segments(cycles, changes, dt, last_tick * dt, tl)
    switches = [(k * dt, c) for k, c in switch_ticks]
    param_changes = [(k * dt, node, name, v) for k, node, name, v in tl.changes
                     if k > 0] if tl else []
    return BagAnalysis(Path(path), p, source, truncated, reason, ticks, cycles, segments,
                       switches, online, series, param_changes)


def with_param_boundaries(changes: list[tuple[int, str]],
                          tl: ParamTimeline) -> list[tuple[int, str]]:
    """Controller changes plus a boundary (same controller) at every parameter change."""
    out = dict(changes)
    for k in tl.change_ticks:
        if k > 0 and k not in out:
            out[k] = label_ticks(changes, np.array([k]))[0] if changes else "unknown"
    return sorted(out.items())


def _segments(cycles: list[CycleResult], changes: list[tuple[int, str]], dt: float,
              t_last: float, tl: ParamTimeline | None = None) -> list[SegmentResult]:
    """One segment per controller stretch; its indices cover its complete cycles."""
    out = []
    bounds = [k for k, _ in changes[1:]]
    for j, (k, who) in enumerate(changes):
        t0 = k * dt
        t1 = bounds[j] * dt if j < len(bounds) else t_last
        mine = [c for c in cycles if c.controller == who and c.sums is not None
                and t0 <= c.t_a and c.t_b <= max(t1, t0) + 1e-9]
        total: WindowSums | None = None
        for c in mine:
            assert c.sums is not None  # filtered above
            total = c.sums if total is None else total + c.sums
        changed: tuple[tuple[str, Any], ...] = ()
        if tl is not None:
            now = tl.at(k)
            changed = tuple((n, now[n]) for n in sorted(now)
                            if now[n] != tl.start.get(n) and n != "run.controller")
        out.append(SegmentResult(who, t0, t1, len(mine), total.indices() if total else None,
                                 changed))
    return out


__all__ = [
    "MIXED",
    "BagAnalysis",
    "CycleResult",
    "SegmentResult",
    "analyze_bag",
    "controller_changes",
    "label_ticks",
    "online_indices",
    "ticks_of_changes",
    "with_param_boundaries",
]
