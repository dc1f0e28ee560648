"""Where a lockstep tick's wall time goes, from the trace files of a graph run (ROS-free).

Reads what :mod:`.trace` wrote (one ``<node>-<pid>.npy`` per process) and cuts every tick
of the state -> command -> state loop into consecutive segments between measured
timestamps, so that the segments of a tick add up to its period exactly: the sim's
publishing, DDS delivery of the joint state (DDS source -> reception timestamp), the
controller's wake-up, take, verification, decoding, checks, its other inputs, the control
law, encoding, signing and publishing of the command, the delivery back, the sim's
wake-up, take, verification, decoding and checks, the physics step, sampling and encoding,
signing. Off the loop it gives each node's main-thread CPU per tick and the recorder's
per-message costs.
"""
from __future__ import annotations

import itertools
import statistics
from pathlib import Path
from typing import NamedTuple

import numpy as np

from hexapod_common.core import topics as T
from .trace import (
    CHECKED,
    DECODED,
    LAW0,
    LAW1,
    PREP0,
    PUB0,
    PUB1,
    SIGN0,
    SIGN1,
    STEP0,
    STEP1,
    TAKE0,
    TAKE1,
    TOPIC_ID,
    VERIFIED,
    WAKE,
)

JS, CMD = TOPIC_ID[T.JOINT_STATES], TOPIC_ID[T.JOINT_COMMANDS]
#: Segments of a tick, in order: (name, where it runs).
SEGMENTS = (
    ("sim: publish foot forces, then joint states until their DDS write", "sim"),
    ("DDS delivery of the joint state (source -> reception stamp)", "dds"),
    ("controller wake-up: reception -> its wait returns", "ctrl"),
    ("controller hot loop: wait returned -> take starts", "ctrl"),
    ("controller take (rcl take_message)", "ctrl"),
    ("controller verify (BLAKE2b tag, replay check)", "ctrl"),
    ("controller decode", "ctrl"),
    ("controller checks (finite, stamps)", "ctrl"),
    ("controller other inputs: take, verify, decode, check foot forces and reference", "ctrl"),
    ("controller control law", "ctrl"),
    ("controller encode command", "ctrl"),
    ("controller sign command", "ctrl"),
    ("controller publish until the DDS write", "ctrl"),
    ("DDS delivery of the command (source -> reception stamp)", "dds"),
    ("sim wake-up: reception -> its wait returns", "sim"),
    ("sim hot loop: wait returned -> take starts", "sim"),
    ("sim take (rcl take_message)", "sim"),
    ("sim verify", "sim"),
    ("sim decode", "sim"),
    ("sim checks", "sim"),
    ("sim: command accepted -> physics step starts", "sim"),
    ("sim physics step (one control period)", "sim"),
    ("sim: step end -> sampling starts (switch channel, parameter records)", "sim"),
    ("sim sample + encode the 3 state topics", "sim"),
    ("sim sign the 3 state topics", "sim"),
    ("sim: /clock, deadline, publish start", "sim"),
)
ROUND_TRIP = (0, 20)  # segments from the sim's publish to the command accepted


class Breakdown(NamedTuple):
    """Medians and means (ms) per segment over the ticks that have every timestamp."""

    ticks: int
    median_ms: list[float]
    mean_ms: list[float]
    period_median_ms: float
    round_trip_median_ms: float
    cpu_per_tick_ms: dict[str, float]      # main-thread CPU per tick, per process
    other_cpu_per_tick_ms: dict[str, float]  # CPU of the process's other (DDS) threads
    recorder_us: dict[str, float]          # recorder: median per message of each stage


def load(folder: Path) -> dict[str, np.ndarray]:
    """Trace rows per process name (``<name>-<pid>.npy``; the newest file of a name)."""
    out: dict[str, np.ndarray] = {}
    for f in sorted(folder.glob("*.npy"), key=lambda p: p.stat().st_mtime):
        out[f.stem.rsplit("-", 1)[0]] = np.load(f)
    return out


def _first(rows: np.ndarray, kind: int, topic: int | None = None) -> dict[int, np.ndarray]:
    """stamp -> the first row of ``kind`` (and ``topic``) with that stamp."""
    sel = rows[rows[:, 0] == kind]
    if topic is not None:
        sel = sel[sel[:, 1] == topic]
    out: dict[int, np.ndarray] = {}
    for r in sel:
        out.setdefault(int(r[2]), r)
    return out


def _cpu_per_tick(rows: np.ndarray, t_from: int, t_to: int, ticks: int, col: int = 4
                  ) -> float:
    """CPU ms per tick between two wall times (col 4: main thread, 5: whole process)."""
    w = rows[(rows[:, 0] == WAKE) & (rows[:, 3] >= t_from) & (rows[:, 3] <= t_to)]
    if len(w) < 2 or ticks <= 0 or w[-1, 3] == w[0, 3]:
        return float("nan")
    share = float(w[-1, col] - w[0, col]) / float(w[-1, 3] - w[0, 3])  # CPU s per wall s
    return share * (t_to - t_from) / ticks / 1e6


def breakdown(traces: dict[str, np.ndarray], controller: str, skip: int = 100) -> Breakdown:
    """The breakdown of a lockstep run whose controller in charge is ``controller``
    (``pd_p`` or ``pd_pf``); the first ``skip`` ticks (connections warming up) are left out."""
    sim, ctrl = traces["hexapod_sim"], traces[f"{controller}_controller"]
    pub0 = _first(sim, PUB0)
    js_pub1 = _first(sim, PUB1, JS)
    c_take0, c_take1 = _first(ctrl, TAKE0, JS), _first(ctrl, TAKE1, JS)
    c_ver, c_dec, c_chk = _first(ctrl, VERIFIED, JS), _first(ctrl, DECODED, JS), _first(
        ctrl, CHECKED, JS)
    law0, law1 = _first(ctrl, LAW0), _first(ctrl, LAW1)
    c_sign0 = _first(ctrl, SIGN0, CMD)
    c_pub0 = _first(ctrl, PUB0, CMD)
    s_take0, s_take1 = _first(sim, TAKE0, CMD), _first(sim, TAKE1, CMD)
    s_ver, s_dec, s_chk = _first(sim, VERIFIED, CMD), _first(sim, DECODED, CMD), _first(
        sim, CHECKED, CMD)
    step0, step1 = _first(sim, STEP0), _first(sim, STEP1)
    order = sim[np.argsort(sim[:, 3], kind="stable")]
    prep_t = np.sort(order[order[:, 0] == PREP0, 3])
    # The sim's signing of the next tick's messages: (SIGN0, SIGN1) pairs in time order.
    sig = order[(order[:, 0] == SIGN0) | (order[:, 0] == SIGN1)]
    pairs: dict[int, list[tuple[int, int]]] = {}
    for a, b in itertools.pairwise(sig):
        if a[0] == SIGN0 and b[0] == SIGN1 and a[1] in (JS, TOPIC_ID[T.FOOT_FORCES],
                                                        TOPIC_ID[T.HIP_STATES]):
            pairs.setdefault(int(a[2]), []).append((int(a[3]), int(b[3])))
    c_wakes = np.sort(ctrl[ctrl[:, 0] == WAKE, 3])
    s_wakes = np.sort(sim[sim[:, 0] == WAKE, 3])

    def woke(wakes: np.ndarray, recv: int, take: int) -> int:
        """The wait's return that led to the take: the last before it, not before the
        sample's reception (the loop was already awake: then the wake-up is 0)."""
        i = int(np.searchsorted(wakes, take, side="right")) - 1
        return max(int(wakes[i]), recv) if i >= 0 else recv

    stamps = sorted(pub0)
    rows: list[list[float]] = []
    for s, s_next in zip(stamps[skip:], stamps[skip + 1:]):
        need = (js_pub1, c_take0, c_take1, c_ver, c_dec, c_chk, law0, law1, c_sign0, c_pub0,
                s_take0, s_take1, s_ver, s_dec, s_chk, step0, step1)
        if any(s not in d for d in need) or len(pairs.get(s_next, ())) != 3:
            continue
        tk = c_take1[s]
        j = int(np.searchsorted(prep_t, step1[s][3]))
        if j >= len(prep_t):
            continue
        sg = sorted(pairs[s_next])
        st = s_take1[s]
        b = [pub0[s][3], tk[4], tk[5], woke(c_wakes, tk[5], c_take0[s][3]), c_take0[s][3],
             tk[3], c_ver[s][3], c_dec[s][3], c_chk[s][3], law0[s][3], law1[s][3],
             c_sign0[s][3], c_pub0[s][3], st[4], st[5], woke(s_wakes, st[5], s_take0[s][3]),
             s_take0[s][3], st[3], s_ver[s][3], s_dec[s][3], s_chk[s][3], step0[s][3],
             step1[s][3], prep_t[j]]
        seg = [float(y - x) for x, y in itertools.pairwise(b)]
        # sampling/encoding = the gaps before each signature; signing = the signatures
        enc, sign, last = 0.0, 0.0, float(prep_t[j])
        for a0, a1 in sg:
            enc += a0 - last
            sign += a1 - a0
            last = a1
        seg += [enc, sign, float(pub0[s_next][3]) - last]
        rows.append(seg)
    if not rows:
        raise ValueError("trace: no tick has every timestamp (was the run traced, lockstep, "
                         f"with {controller} in charge?)")
    arr = np.array(rows) / 1e6
    n = len(rows)
    t_from, t_to = int(pub0[stamps[skip]][3]), int(pub0[stamps[skip + n]][3])
    ticks = sum(1 for s in stamps if t_from <= pub0[s][3] < t_to)
    cpu = {name: _cpu_per_tick(r, t_from, t_to, ticks) for name, r in traces.items()}
    other = {name: _cpu_per_tick(r, t_from, t_to, ticks, 5) - cpu[name]
             for name, r in traces.items()}
    rec: dict[str, float] = {}
    if "metrics" in traces:
        m = traces["metrics"]
        m = m[np.argsort(m[:, 3], kind="stable")]
        stages: dict[str, list[int]] = {"take": [], "verify": [], "decode": [], "checks": []}
        for a, b in itertools.pairwise(m):
            key = {(TAKE0, TAKE1): "take", (TAKE1, VERIFIED): "verify",
                   (VERIFIED, DECODED): "decode", (DECODED, CHECKED): "checks"}.get(
                       (int(a[0]), int(b[0])))
            if key is not None and a[1] == b[1]:
                stages[key].append(int(b[3] - a[3]))
        rec = {k: statistics.median(v) / 1e3 for k, v in stages.items() if v}
    rt = arr[:, ROUND_TRIP[0]:ROUND_TRIP[1]].sum(axis=1)
    return Breakdown(n, [float(x) for x in np.median(arr, axis=0)],
                     [float(x) for x in arr.mean(axis=0)], float(np.median(arr.sum(axis=1))),
                     float(np.median(rt)), cpu, other, rec)


def format_breakdown(b: Breakdown) -> list[str]:
    """Printable lines: one per segment (median, mean ms, share of the mean period)."""
    total = sum(b.mean_ms)
    lines = [f"  {'segment':78s} {'median':>7s} {'mean':>7s} {'share':>6s}"]
    for (name, _), med, mean in zip(SEGMENTS, b.median_ms, b.mean_ms):
        lines.append(f"  {name:78s} {med:7.3f} {mean:7.3f} {100 * mean / total:5.1f}%")
    lines.append(f"  {'tick period (sum of the segments)':78s} {b.period_median_ms:7.3f} "
                 f"{total:7.3f}")
    lines.append(f"  {'round trip: sim publish -> command accepted':78s} "
                 f"{b.round_trip_median_ms:7.3f}")
    lines.append("  main-thread CPU per tick (ms): " + ", ".join(
        f"{k} {v:.3f}" for k, v in sorted(b.cpu_per_tick_ms.items())))
    lines.append("  other threads' (DDS) CPU per tick (ms): " + ", ".join(
        f"{k} {v:.3f}" for k, v in sorted(b.other_cpu_per_tick_ms.items())))
    if b.recorder_us:
        lines.append("  recorder per message, median (us): " + ", ".join(
            f"{k} {v:.1f}" for k, v in b.recorder_us.items()))
    return lines


__all__ = ["SEGMENTS", "Breakdown", "breakdown", "format_breakdown", "load"]
