"""The in-process closed loop: physics + references + controller + actuator, one or many runs.

Per control tick k (period Delta t, ``p.substeps`` physics steps):
    obs_k = observe(state, T_{k-1});  T_C = control_law(obs_k, ref_k);  T_k = saturate(T_C);
    integrate one period holding T_k.
The ROS graph does exactly the same across processes (sim node / controller node), with the
same compiled functions, so a lockstep graph run reproduces these numbers.

Any registered controller runs here (registry.py). PD-P, and PD-P&F with its force loop at
the tick, take the compiled path (:func:`run_ticks`); PD-P&F with ``force_loop: drive`` a
compiled loop around the drive (:func:`run_drive_ticks`). A plug-in's plain-Python law
runs a per-tick Python loop around the compiled observe and drive (:func:`run_plugin_ticks`):
obs_k = observe(state, T_acting); command = law(obs_k); the drive (hexapod_sim.core.drive)
evaluates the command at every physics step of the period. A torque-only command gives the
compiled path's numbers.

Batch runs (:func:`run_batch`) execute many parameter sets at once: blocks of cases with the
case index innermost (batch_loop.py), blocks in parallel; every case gets the numbers of its
single run. A diverged case is reported as diverged, its samples are not used.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Mapping, Sequence

import numba
import numpy as np

from hexapod_common.core.jit import njit

from hexapod_sim.core.actuator import saturate
from hexapod_sim.core.drive import drive_advance
from hexapod_sim.core.engine import (advance_prepared, initial_state, observe, observe_prepared,
                                     scratch)
from hexapod_sim.core.uneven_ground import GroundDraws, GroundRecord, touchdowns
from hexapod_common.core.gait import Reference, reference
from hexapod_common.core.index_sums import ACC_SIZE, accumulate
from hexapod_common.core.layout import (O_FP, O_HF, O_HP, O_THV, O_TQ, OBS_SHAPE, P_L1,
                                        P_L2, P_TMAX, model_vector)
from hexapod_common.core.errors import ParameterError
from hexapod_common.core.params import (N_LEGS, HexapodParams, check_controller,
                                        controller_group, controller_names)

from . import registry
from .batch_loop import MAX_BLOCK, block_plan, run_blocks
from .controller_api import call_law
from .builtin import PdPf
from .controllers import (PD_P, PD_PF, PD_PF_DRIVE, control_law, controller_code,
                          gain_vector, pd_pf_drive_command)

#: Ticks per compiled block of a single run (bounds reference memory, paces progress bars).
BLOCK_TICKS = 2000
#: Parameter groups a run can change at a tick (those the model vector and gains hold);
#: every registered controller's group too (:func:`changeable`).
CHANGEABLE = ("ground.", "actuator.", "pd_p.", "pd_pf.")


def changeable() -> tuple[str, ...]:
    """Prefixes of the parameters a run can change at a tick: ground, actuator and every
    registered controller's group."""
    return ("ground.", "actuator.") + tuple(f"{controller_group(c)}."
                                            for c in controller_names())


def compiled_code(controller: str, p: HexapodParams) -> int | None:
    """The compiled law of ``controller`` with parameters ``p``: PD_P, PD_PF (torque-only),
    PD_PF_DRIVE (PD-P&F's force loop in the drive), or None (a plain-Python law)."""
    if registry.is_compiled(controller, p):
        return controller_code(controller)
    if registry.load(controller) is PdPf:
        return PD_PF_DRIVE
    return None


@njit(cache=True)
def run_ticks(s, P, code, gains, theta_d, theta_vel_d, torque, substeps, k0, obs_out,  # type: ignore[no-untyped-def]
              cmd_out, rec_offset):
    """Run ticks k0 .. k0 + len(theta_d) - 1 in place on state ``s`` and held ``torque``.

    Records obs of tick k into obs_out[k - rec_offset] and the demanded torque into
    cmd_out[k - rec_offset] when that row exists. Returns the number of ticks completed
    (less than requested if the state diverged).
    """
    obs = np.empty((9, N_LEGS, 2))
    demand = np.empty((N_LEGS, 2))
    fh, work, ff, qdd = scratch()
    l1, l2, t_max = P[P_L1], P[P_L2], P[P_TMAX]
    n = theta_d.shape[0]
    for j in range(n):
        # the observation's state part (trig, body and ground forces, factored mass
        # matrix) is the first physics step's: computed once, used by both
        observe_prepared(s, torque, P, obs, fh, work, ff, qdd)
        control_law(code, gains, obs, theta_d[j], theta_vel_d[j], l1, l2, demand)
        r = k0 + j - rec_offset
        if 0 <= r < obs_out.shape[0]:
            obs_out[r] = obs
            cmd_out[r] = demand
        saturate(demand, t_max, torque)
        if not advance_prepared(s, torque, P, substeps, fh, work, ff, qdd):
            return j
    return n


@njit(cache=True)
def run_drive_ticks(s, P, gains, theta_d, theta_vel_d, torque, substeps, obs_out,  # type: ignore[no-untyped-def]
                    cmd_out):
    """PD-P&F with its force loop in the drive, compiled: per tick, observe, then the drive
    holds kp = K_f Kp, kd = K_f Kd, k_force = K_f, setpoints the tick's references (the
    numbers of builtin.PdPf.law through :func:`run_plugin_ticks`). ``gains``: (Kp1, Kd1,
    Kp2, Kd2, K_f). Records obs_out[j], cmd_out[j] (the first step's T). Returns the ticks
    completed."""
    fh, work, ff, qdd = scratch()
    cmd = np.zeros((6, N_LEGS, 2))
    n = theta_d.shape[0]
    for j in range(n):
        observe_prepared(s, torque, P, obs_out[j], fh, work, ff, qdd)
        pd_pf_drive_command(gains, theta_d[j], theta_vel_d[j], cmd)
        if not drive_advance(s, cmd, P, substeps, fh, work, ff, qdd, cmd_out[j], torque):
            return j
    return n


def run_plugin_ticks(s: np.ndarray, P: np.ndarray, ctrl: Any, theta_d: np.ndarray,
                     theta_vel_d: np.ndarray, torque: np.ndarray, substeps: int, k0: int,
                     period: float, obs_out: np.ndarray, cmd_out: np.ndarray) -> int:
    """Run len(theta_d) ticks of controller instance ``ctrl`` (its ``law``) in place on
    state ``s`` and the acting ``torque`` (6, 2), the first being tick ``k0`` (time
    k0 * period s), through the drive. Records every tick's sample into obs_out[j] and the
    first physics step's unsaturated torque into cmd_out[j]. Returns the number of ticks
    completed (less than requested if the state diverged)."""
    fh, work, ff, qdd = scratch()
    n = int(theta_d.shape[0])
    for j in range(n):
        obs = obs_out[j]
        observe_prepared(s, torque, P, obs, fh, work, ff, qdd)
        cmd = call_law(ctrl, (k0 + j) * period, obs, theta_d[j], theta_vel_d[j])
        if not drive_advance(s, cmd, P, substeps, fh, work, ff, qdd, cmd_out[j], torque):
            return j
    return n


@dataclass(frozen=True)
class RunResult:
    """Samples of one run at the control ticks 0..N (obs) and the demands of ticks 0..N-1.

    ``obs`` (N+1, 9, 6, 2) follows layout.OBS_FIELDS; ``command`` (N, 6, 2) is T_C (N m);
    ``reference`` holds the desired trajectories at the same N+1 instants. ``diverged_at``
    is the time (s) of the last good tick if the run blew up, else None. ``switches`` lists
    (first tick, controller) of every controller in charge, starting with tick 0.
    """

    params: HexapodParams
    controller: str
    t: np.ndarray
    obs: np.ndarray
    command: np.ndarray
    reference: Reference
    diverged_at: float | None = None
    switches: tuple[tuple[int, str], ...] = ()
    param_changes: tuple[tuple[int, dict[str, Any]], ...] = ()
    #: uneven ground (uneven_ground.py): the draws and each foot's touchdowns; None if uniform
    ground: GroundRecord | None = None

    def controller_at(self, k: int) -> str:
        """Controller that computed the command of tick k."""
        return [c for start, c in self.switches if start <= k][-1] if self.switches \
            else self.controller


def tick_count(p: HexapodParams, duration: float) -> int:
    """Number of control periods in ``duration`` seconds (must be a whole number)."""
    n = duration / p.sim.control_period
    if n < 1 or abs(n - round(n)) > 1e-6:
        raise ParameterError("run.duration", duration,
                             f"a positive multiple of sim.control_period = "
                             f"{p.sim.control_period:g} s")
    return int(round(n))


#: Bytes one in-process run holds per control tick: samples, commands, the reference and
#: its temporaries (measured order of magnitude, rounded up).
BYTES_PER_TICK = 4096


def max_in_memory_ticks() -> int:
    """Ticks one in-process run may hold: half of this machine's physical memory."""
    import os

    try:
        mem = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        mem = 8 << 30
    return int(mem // 2 // BYTES_PER_TICK)


def check_fits_in_memory(p: HexapodParams, duration: float, n: int) -> None:
    """Raise ParameterError (run.duration) if a run of ``n`` ticks cannot be held in memory."""
    limit = max_in_memory_ticks()
    if n > limit:
        raise ParameterError("run.duration", duration,
                             f"at most {limit * p.sim.control_period:g} s in one in-process run "
                             f"at this control rate: it keeps every tick in memory (~"
                             f"{BYTES_PER_TICK // 1024} kB each, half of this machine's "
                             f"memory); the node graph (scripts/run_graph.sh) streams longer "
                             f"runs")


def run(p: HexapodParams, controller: str | None = None, duration: float | None = None,
        progress: Callable[[int, int], None] | None = None,
        switches: Sequence[tuple[float, str]] = (),
        param_changes: Sequence[tuple[float, Mapping[str, Any]]] = (),
        ground: GroundDraws | None = None) -> RunResult:
    """One closed-loop run from the initial state; records every tick.

    controller: any registered name or module:Class (default p.run.controller); duration
    in s (default p.run.duration). ``switches``: (time s, controller) hand-overs; the new controller
    computes the command of the first tick at or after that time, as in the graph.
    ``param_changes``: (time s, {dotted name: value}) live changes (ground, actuator,
    gains); the first tick at or after that time is observed and integrated with them, as
    the sim applies a change at the next tick boundary.
    ``progress(done, total)`` is called after every block of ticks.
    ``ground``: uneven ground, each foot's factors drawn per touchdown (uneven_ground.py);
    the result's ``ground`` records the factors used (check ``overflowed``: a foot touched
    down more often than pairs were drawn).
    """
    controller = controller or p.run.controller
    duration = p.run.duration if duration is None else duration
    n = tick_count(p, duration)
    check_fits_in_memory(p, duration, n)
    schedule = [(0, controller)] + sorted(
        (int(math.ceil(ts / p.sim.control_period - 1e-9)), c) for ts, c in switches)
    for _, c in schedule:
        registry.load(check_controller(c))
    changes = sorted(((int(math.ceil(ts / p.sim.control_period - 1e-9)), dict(v))
                      for ts, v in param_changes), key=lambda c: c[0])
    allowed = changeable()
    for _, values in changes:
        for name, value in values.items():
            if not name.startswith(allowed):
                raise ParameterError(name, value, "a change during a run only of "
                                     + ", ".join(g + "*" for g in allowed))
    params_at = [(0, p)]
    for k, values in changes:
        params_at.append((k, params_at[-1][1].with_values(**values)))
    t = np.arange(n + 1) * p.sim.control_period
    ref = reference(p, t)
    P = model_vector(p)
    s = initial_state(p) if ground is None else ground.attach(initial_state(p))
    torque = np.zeros((N_LEGS, 2))
    obs = np.full((n + 1,) + OBS_SHAPE, np.nan)
    cmd = np.full((n, N_LEGS, 2), np.nan)
    diverged_at = None
    cuts = sorted({k for k, _ in schedule + params_at if 0 < k < n}
                  | set(range(0, n, BLOCK_TICKS)) | {n})
    active: tuple[str, Any, Any] | None = None  # (name, its parameters, instance) in charge
    for k0, k1 in zip(cuts[:-1], cuts[1:]):
        who = [c for k, c in schedule if k <= k0][-1]
        cur = [q for k, q in params_at if k <= k0][-1]
        if k0 > 0 and any(k == k0 for k, _ in params_at):
            P = model_vector(cur)
        code = compiled_code(who, cur)
        if code in (PD_P, PD_PF):
            active = None
            done = run_ticks(s, P, code, gain_vector(cur.gains(who)),
                             ref.theta[k0:k1], ref.theta_vel[k0:k1], torque, p.substeps, k0,
                             obs[k0:k1], cmd[k0:k1], k0)
        elif code == PD_PF_DRIVE:
            active = None
            done = run_drive_ticks(s, P, gain_vector(cur.gains(who)), ref.theta[k0:k1],
                                   ref.theta_vel[k0:k1], torque, p.substeps, obs[k0:k1],
                                   cmd[k0:k1])
        else:
            if active is None or active[0] != who or active[1] != cur.gains(who):
                # takes charge (or its parameters changed): a fresh, reset instance
                active = (who, cur.gains(who), registry.create(who, cur))
            done = run_plugin_ticks(s, P, active[2], ref.theta[k0:k1], ref.theta_vel[k0:k1],
                                    torque, p.substeps, k0, p.sim.control_period,
                                    obs[k0:k1], cmd[k0:k1])
        if progress is not None:
            progress(k0 + done, n)
        if done < k1 - k0:
            diverged_at = float(t[k0 + done])
            break
    else:
        if any(k == n for k, _ in params_at[1:]):
            P = model_vector([q for k, q in params_at if k <= n][-1])
        observe(s, torque, P, obs[n])
    applied = tuple((k, c) for k, c in schedule if k < n)
    record = None if ground is None else GroundRecord(ground, tuple(int(c) for c in
                                                                    touchdowns(s)))
    return RunResult(p, controller, t, obs, cmd, ref, diverged_at, applied,
                     tuple((k, v) for k, v in changes if k <= n), record)


@dataclass(frozen=True)
class Case:
    """One member of a batch: parameters and the controller that runs them."""

    params: HexapodParams
    controller: str


def batch_code(case: Case) -> int | None:
    """The compiled batch's code of ``case`` (PD_P, PD_PF, PD_PF_DRIVE), or None when its law
    is plain Python (a plug-in: run one by one)."""
    return compiled_code(case.controller, case.params)


@dataclass(frozen=True)
class BatchResult:
    """Samples of ticks k_a..k_b of every case (``obs`` (cases, k_b-k_a+1, 9, 6, 2)),
    the reference over the same ticks, and which cases finished without diverging."""

    cases: tuple[Case, ...]
    t: np.ndarray
    obs: np.ndarray
    reference: Reference
    ok: np.ndarray


def shared_reference_key(p: HexapodParams) -> tuple[object, ...]:
    """What cases of one batch must share: the reference trajectory at the control ticks
    depends on the robot, the gait and the control period (not on the physics step)."""
    return (p.robot, p.gait, p.sim.control_period)


def _batch_ticks(cases: Sequence[Case], duration: float) -> int:
    """Ticks of a batch of ``duration`` s, after checking its cases share one reference."""
    if not cases:
        raise ValueError("a batch needs at least one case")
    p0 = cases[0].params
    key = shared_reference_key(p0)
    for c in cases:
        if shared_reference_key(c.params) != key:
            raise ParameterError("gait", "differs between cases",
                                 "one robot, gait and control period per batch (split the "
                                 "batch)")
    return tick_count(p0, duration)


def run_batch(cases: Sequence[Case], duration: float, record_from: float) -> BatchResult:
    """Run every case for ``duration`` s in parallel; keep the ticks from ``record_from`` s on.

    All cases must share robot geometry, gait and control period (they differ in ground,
    actuator, body, gains and physics step ``sim.dt``), so that they share one reference
    trajectory at the control ticks.
    """
    n = _batch_ticks(cases, duration)
    p0 = cases[0].params
    k_a = int(math.floor(record_from / p0.sim.control_period + 1e-9))
    if not 0 <= k_a <= n:
        raise ParameterError("record_from", record_from, f"a time in [0, {duration:g}] s")
    t = np.arange(n + 1) * p0.sim.control_period
    ref = batch_reference(p0, n)
    obs = np.full((len(cases), n + 1 - k_a) + OBS_SHAPE, np.nan)
    ok = np.zeros(len(cases), dtype=np.bool_)

    def plug_in(j: int, r: RunResult) -> None:
        obs[j] = r.obs[k_a:]
        ok[j] = r.diverged_at is None

    fast = _run_plug_ins(cases, duration, plug_in)
    _run_compiled_rows(cases, fast, ref, n, k_a, -1, obs, ok, np.zeros((0, 1, ACC_SIZE)),
                       np.zeros(0, dtype=np.bool_))
    window_ref = Reference(*(_read_only(a[k_a:]) for a in ref))
    return BatchResult(tuple(cases), t[k_a:], obs, window_ref, ok)


@dataclass(frozen=True)
class ScoredBatch:
    """The index sums of ticks k_a..k_b of every case, cut into ``windows`` consecutive
    windows of equal length (``sums`` (cases, windows, ACC_SIZE): the accumulators of
    hexapod_common.core.index_sums), and which cases finished without diverging with every
    value of those samples finite (``ok``); ``window`` (t_a, t_b) s of the whole span."""

    cases: tuple[Case, ...]
    window: tuple[float, float]
    sums: np.ndarray
    ok: np.ndarray


def score_batch(cases: Sequence[Case], duration: float, window: tuple[int, int],
                windows: int = 1) -> ScoredBatch:
    """Run every case for ``duration`` s in parallel and score ticks ``window`` = (k_a, k_b)
    on the fly, without recording them, as ``windows`` consecutive windows of
    (k_b - k_a) / windows ticks each (one per gait cycle, say): what a sweep needs of a run
    (the sums are those of the same samples recorded, to the last bit). Cases as for
    :func:`run_batch`."""
    n = _batch_ticks(cases, duration)
    k_a, k_b = window
    if not 0 <= k_a < k_b <= n:
        raise ParameterError("window", window, f"ticks 0 <= k_a < k_b <= {n}")
    if windows < 1 or (k_b - k_a) % windows:
        raise ParameterError("windows", windows,
                             f"a whole number that divides the {k_b - k_a} ticks scored")
    m = (k_b - k_a) // windows
    p0 = cases[0].params
    ref = batch_reference(p0, n)
    sums = np.full((len(cases), windows, ACC_SIZE), np.nan)
    ok = np.zeros(len(cases), dtype=np.bool_)
    finite = np.ones(len(cases), dtype=np.bool_)

    def plug_in(j: int, r: RunResult) -> None:  # scored from its samples
        for w in range(windows):
            a, b = k_a + w * m, k_a + (w + 1) * m + 1
            s = r.obs[a:b]
            accumulate(sums[j, w], s[:, O_TQ], s[:, O_THV], s[:, O_HF], s[:, O_HP],
                       ref.hip[a:b], s[:, O_FP], ref.foot[a:b])
        ok[j] = r.diverged_at is None
        finite[j] = bool(np.all(np.isfinite(r.obs[k_a:k_b + 1])))

    fast = _run_plug_ins(cases, duration, plug_in)
    _run_compiled_rows(cases, fast, ref, n, k_a, k_b, np.empty((len(cases), 0) + OBS_SHAPE),
                       ok, sums, finite)
    dt = p0.sim.control_period
    return ScoredBatch(tuple(cases), (k_a * dt, k_b * dt), sums, ok & finite)


def _read_only(view: np.ndarray) -> np.ndarray:
    """``view`` (of a kept reference array) made read-only: the result cannot change it."""
    view.flags.writeable = False
    return view


#: The last few batches' reference trajectories, by (shared_reference_key, ticks): every
#: chunk of a sweep shares one (computing it took ~12 % of a chunk of eight 3 s runs).
_BATCH_REFERENCES: dict[tuple[object, ...], Reference] = {}


def batch_reference(p: HexapodParams, n: int) -> Reference:
    """The reference at control ticks 0..n of ``p``, kept per :func:`shared_reference_key`
    and ``n``: shared, so callers must not write into its arrays (they stay writable only
    because the compiled kernels are typed for writable arrays; :func:`run_batch` hands out
    read-only views)."""
    key = (shared_reference_key(p), n)
    ref = _BATCH_REFERENCES.get(key)
    if ref is None:
        ref = reference(p, np.arange(n + 1) * p.sim.control_period)
        if len(_BATCH_REFERENCES) >= 4:
            _BATCH_REFERENCES.pop(next(iter(_BATCH_REFERENCES)))
        _BATCH_REFERENCES[key] = ref
    return ref


def _run_plug_ins(cases: Sequence[Case], duration: float,
                  each: Callable[[int, RunResult], None]) -> list[int]:
    """Run the cases whose law is plain Python (plug-ins) one by one, ``each(j, result)``
    for case j; the indices of the others (compiled laws: one batch)."""
    fast = []
    for j, c in enumerate(cases):
        if batch_code(c) is None:
            each(j, run(c.params, c.controller, duration))
        else:
            fast.append(j)
    return fast


def _run_compiled_rows(cases: Sequence[Case], fast: Sequence[int], ref: Reference, n: int,
                       k_a: int, k_b: int, obs: np.ndarray, ok: np.ndarray, sums: np.ndarray,
                       finite: np.ndarray) -> None:
    """:func:`_run_compiled_batch` on the cases ``fast`` (indices into ``cases``), into those
    rows of ``obs``, ``ok``, ``sums`` and ``finite`` (an array of no rows stays unused);
    straight into them when every case is compiled (the usual batch)."""
    if len(fast) == len(cases):
        _run_compiled_batch(cases, ref, n, k_a, obs, ok, k_b, sums, finite)
        return
    if not fast:
        return
    rows = [a[fast] if len(a) else a for a in (obs, ok, sums, finite)]
    _run_compiled_batch([cases[j] for j in fast], ref, n, k_a, rows[0], rows[1], k_b,
                        rows[2], rows[3])
    for a, r in zip((obs, ok, sums, finite), rows):
        if len(a):
            a[fast] = r


def _run_compiled_batch(cases: Sequence[Case], ref: Reference, n: int, k_a: int,
                        obs: np.ndarray, ok: np.ndarray, k_b: int, sums: np.ndarray,
                        finite: np.ndarray) -> None:
    """Run cases with a compiled law; their samples into ``obs`` (cases, n+1-k_a, 9, 6, 2)
    (or (cases, 0, 9, 6, 2): none), their ok flags into ``ok``, and with k_b >= k_a the sums
    of ticks k_a..k_b into ``sums`` (cases, windows, ACC_SIZE) and finite flags into ``finite``."""
    S = np.stack([initial_state(c.params) for c in cases])
    Ps = np.stack([model_vector(c.params) for c in cases])
    codes = np.array([batch_code(c) for c in cases], dtype=np.int64)
    G = np.stack([gain_vector(c.params.gains(c.controller)) for c in cases])
    substeps = np.array([c.params.substeps for c in cases], dtype=np.int64)
    blocks = block_plan(substeps, numba.get_num_threads())
    width = MAX_BLOCK
    # structure of arrays: per block, one row per state / model entry, one column per case
    Xs = np.zeros((len(blocks), S.shape[1], width))
    PTs = np.zeros((len(blocks), Ps.shape[1], width))
    Gs = np.zeros((len(blocks), G.shape[1], width))
    Cs = np.zeros((len(blocks), width), dtype=np.int64)
    cols = np.zeros((len(blocks), width), dtype=np.int64)
    for j, idx in enumerate(blocks):
        m = idx.size
        Xs[j, :, :m], PTs[j, :, :m], Gs[j, :, :m] = S[idx].T, Ps[idx].T, G[idx].T
        Cs[j, :m], cols[j, :m] = codes[idx], idx
    counts = np.array([b.size for b in blocks], dtype=np.int64)
    block_substeps = np.array([substeps[b[0]] for b in blocks], dtype=np.int64)
    run_blocks(Xs, PTs, Cs, Gs, counts, ref.theta[:n], ref.theta_vel[:n], block_substeps, k_a,
               obs, cols, ok, k_b, ref.hip, ref.foot, sums, finite)


__all__ = ["BLOCK_TICKS", "CHANGEABLE", "BatchResult", "Case", "RunResult", "ScoredBatch",
           "batch_code", "changeable", "compiled_code", "run", "run_batch", "run_drive_ticks",
           "run_plugin_ticks", "run_ticks", "score_batch",
           "shared_reference_key", "tick_count"]
