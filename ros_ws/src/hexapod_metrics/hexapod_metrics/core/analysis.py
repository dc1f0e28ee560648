"""Offline analysis of a bag: the seven indices per gait cycle and per controller segment.

The bag is streamed chunk by chunk: samples are kept only until the gait cycle they belong to
is complete, then reduced to additive :class:`~.indices.WindowSums`, so memory is bounded by
one cycle (plus decimated plot series), not by the bag. The sample convention is the
engine's (indices.py), so the analysis of a graph bag equals the engine's and the metrics
node's numbers.

Cycles are scored by the one scorer (core/cycles.py), as online. Which controller was in
charge at each tick, and whether it commanded each torque, comes from the ``header.frame_id``
of ``/hexapod/joint_states`` (``hexapod_common.core.labels``); a cycle with held or fallback
torques is labelled so, never with the controller's name. Segments are split at changes of
the controller in charge, i.e. at the recorded switches, and at every recorded parameter
change (bag_params.py), each segment naming the values that differ from the start; a
segment's indices are the per-cycle mean over the cycles its controller fully commanded.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from hexapod_common.core import topics as T
from hexapod_common.core.cdr import decode_diagnostic_array
from hexapod_common.core.errors import CdrError
from hexapod_common.core.labels import in_charge
from hexapod_common.core.layout import O_HP, O_TQ
from hexapod_common.core.controller_names import node_of
from hexapod_common.core.param_log import ParamRecord, ParamTimeline
from hexapod_common.core.params import HexapodParams

from ..bag import Bag, BagReadError, iter_joint_state_blocks, open_bag
from .bag_params import bag_params
from .cycles import CYCLE_TOPICS, Cycle, CycleScorer
from .indices import Indices, per_cycle_mean
from .recording import status_indices
from .walking import not_walking

STREAMS = CYCLE_TOPICS
#: At most this many points per plot series (older points are thinned by 2 when exceeded).
MAX_PLOT_POINTS = 20000


#: A gait cycle of the analysis: the one scorer's (core/cycles.py).
CycleResult = Cycle


@dataclass(frozen=True)
class SegmentResult:
    """A stretch of the run under one controller and the indices of its complete cycles."""

    controller: str
    t_start: float
    t_end: float
    cycles: int
    indices: Indices | None
    """The per-cycle mean of its cycles' indices (None if it has none, or one fell)."""
    params: tuple[tuple[str, Any], ...] = ()
    """Parameters in force over the segment that differ from the start values."""
    controller_params: tuple[tuple[str, Any], ...] = ()
    """A joined controller's own parameters (declared by its node, read by the sim when it
    took over: the bag's ``controller`` record); empty for the engine's controllers, whose
    gains are model parameters (``pd_p.*``, ``pd_pf.*``)."""
    fallen: str = ""
    """Why one of its cycles was not a walk (then ``indices`` is None); "" if all were."""


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


def controller_changes(bag: Bag, dt_ns: int) -> list[tuple[int, str]]:
    """(first tick, controller in charge) at the start and at every change of it (the
    controller named by joint_states' frame_id, ``hexapod_common.core.labels``)."""
    frames: dict[str, list[tuple[int, str]]] = {T.JOINT_STATES: []}
    for _ in iter_joint_state_blocks(bag, [T.JOINT_STATES], frames=frames):
        pass
    return ticks_of_changes(frames[T.JOINT_STATES], dt_ns)


def ticks_of_changes(frames: list[tuple[int, str]], dt_ns: int,
                     into: list[tuple[int, str]] | None = None) -> list[tuple[int, str]]:
    """(stamp ns, frame_id) changes -> (tick, controller in charge) at each change of the
    controller (appended to ``into`` if given); an empty frame_id is 'unknown'."""
    out = [] if into is None else into
    for stamp, frame in frames:
        who = in_charge(frame)
        if not out or out[-1][1] != who:
            out.append((int(round(stamp / dt_ns)), who))
    return out


def label_ticks(changes: list[tuple[int, str]], ticks: npt.ArrayLike) -> np.ndarray:
    """The controller of each tick from (first tick, controller) changes."""
    starts = np.array([k for k, _ in changes], dtype=np.int64)
    names = np.array([c for _, c in changes] or ["unknown"], dtype=object)
    pos = np.searchsorted(starts, ticks, side="right") - 1
    return names[np.clip(pos, 0, None)]


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
        p, source, tl, records = bag_params(bag)
        dt = p.sim.control_period
        dt_ns = int(round(dt * 1e9))
        m = int(round(p.cycle_time / dt))
        indices_raw: dict[str, list[tuple[int, bytes]]] = {T.INDICES: []}  # same pass
        # controller changes (joint_states' frame_id, found vectorised in the same pass as
        # the decoding) and, among them, a boundary at every parameter change
        frames: dict[str, list[tuple[int, str]]] = {T.JOINT_STATES: []}
        switch_ticks: list[tuple[int, str]] = []
        changes: list[tuple[int, str]] = []
        series = PlotSeries(stride=max(1, bag.topics[T.JOINT_STATES].message_count
                                       // MAX_PLOT_POINTS))

        def plot(k0: int, k1: int, obs: np.ndarray, ref: dict[str, np.ndarray]) -> None:
            sel = slice(0, k1 - k0, series.stride)  # ticks k0 .. k1-1
            sig = np.stack([np.abs(ref["hip"][sel, 0, 0] - obs[sel, O_HP, 0, 0]),
                            np.abs(ref["hip"][sel, 0, 1] - obs[sel, O_HP, 0, 1]),
                            obs[sel, O_TQ, 0, 0], obs[sel, O_TQ, 0, 1]], axis=1)
            ks = np.arange(k0, k1)[sel]
            series.add(ks * dt, sig, label_ticks(changes, ks))

        scorer = CycleScorer(m, dt, on_samples=plot, walk=lambda sums: not_walking(sums, p))
        cycles: list[CycleResult] = []
        ticks = 0
        last_tick = 0
        for topic, arrays in iter_joint_state_blocks(bag, STREAMS, frames=frames,
                                                     others=indices_raw):
            if frames[T.JOINT_STATES]:  # labels of ticks up to the newest state are final
                for stamp, frame in frames[T.JOINT_STATES]:
                    scorer.add_frame(int(round(stamp / dt_ns)), frame)
                ticks_of_changes(frames[T.JOINT_STATES], dt_ns, into=switch_ticks)
                frames[T.JOINT_STATES].clear()
                changes = (with_param_boundaries(switch_ticks, tl) if tl is not None
                           else list(switch_ticks))
            k = np.rint(arrays.stamps / dt_ns).astype(np.int64)
            scorer.add_block(topic, k, arrays.position, arrays.velocity, arrays.effort)
            if topic == T.JOINT_STATES:
                ticks += len(k)
                last_tick = max(last_tick, int(k.max(initial=-1)))
            cycles += scorer.take()
        cycles += scorer.take(final=True)
        online = [r for _, raw in indices_raw[T.INDICES] for r in _online_records(raw)]
        truncated, reason = bag.truncated, bag.truncation_reason
    if ticks == 0:
        why = f" (truncated: {reason})" if truncated else ""
        raise BagReadError(f"{path}: no hexapod samples in the readable part of the bag{why}")
    segments = [_with_controller_params(s, int(round(s.t_start / dt)), records)
                for s in _segments(cycles, changes, dt, last_tick * dt, tl)]
    switches = [(k * dt, c) for k, c in switch_ticks]
    param_changes = [(k * dt, node, name, v) for k, node, name, v in tl.changes
                     if k > 0] if tl else []
    return BagAnalysis(Path(path), p, source, truncated, reason, ticks, cycles, segments,
                       switches, online, series, param_changes)


#: Parameters every rclpy node declares: not the controller's own.
_ROS_OWN = ("use_sim_time", "start_type_description_service")


def _with_controller_params(s: SegmentResult, tick: int,
                            records: tuple[ParamRecord, ...]) -> SegmentResult:
    """``s`` with its controller's own parameters: the newest ``controller`` record of its
    node at or before the segment's first tick (a joined controller; see SegmentResult)."""
    node = node_of(s.controller)
    mine = [r for r in records if r.kind == "controller" and r.node == node and r.tick <= tick]
    if not mine:
        return s
    values = max(mine, key=lambda r: r.tick).values
    return replace(s, controller_params=tuple(sorted(
        (n, v) for n, v in values.items() if n not in _ROS_OWN)))


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
    """One segment per controller stretch; its indices are the per-cycle mean of its
    complete cycles (indices.per_cycle_mean: not the index of their union)."""
    out = []
    bounds = [k for k, _ in changes[1:]]
    for j, (k, who) in enumerate(changes):
        t0 = k * dt
        t1 = bounds[j] * dt if j < len(bounds) else t_last
        mine = [c for c in cycles if c.controller == who and c.sums is not None
                and t0 <= c.t_a and c.t_b <= max(t1, t0) + 1e-9]
        fell = next((f"cycle {c.cycle}: {c.fallen}" for c in mine if c.fallen), "")
        scored = [c.indices for c in mine]
        mean = (per_cycle_mean([i for i in scored if i is not None])
                if mine and not fell else None)
        changed: tuple[tuple[str, Any], ...] = ()
        if tl is not None:
            now = tl.at(k)
            changed = tuple((n, now[n]) for n in sorted(now)
                            if now[n] != tl.start.get(n) and n != "run.controller")
        out.append(SegmentResult(who, t0, t1, len(mine), mean,
                                 changed, fallen=fell))
    return out


__all__ = [
    "BagAnalysis",
    "CycleResult",
    "SegmentResult",
    "analyze_bag",
    "controller_changes",
    "label_ticks",
    "ticks_of_changes",
    "with_param_boundaries",
]
