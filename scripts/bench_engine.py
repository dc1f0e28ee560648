#!/usr/bin/env python3
"""Speed benchmarks S1-S3 of the in-process engine (quality.md), printed as one table.

S1  one closed-loop rollout of the base case (10 kHz physics, 1 kHz control), serial, both
    controllers: simulated seconds per wall second, median of 5 after a warm-up compile.
S2  the batched engine as sweeps, tuning and the report run it (closed_loop.score_batch:
    structure-of-arrays blocks of cases, prange over blocks, all cores, the last cycle
    scored on the fly): a ground sweep x both controllers, simulated seconds summed over
    cases per wall second, median of 3; also recording the last cycle (run_batch, the
    Python API for the samples of many runs).
S3  physics step rate against the same planar model in MuJoCo (hexapod_sim.mujoco_model,
    same dt, contacts off): one leg (our compiled step loop vs mj_step from a Python loop,
    mj_step(nstep=N) and mujoco.rollout), six legs (engine.advance vs the six-leg MuJoCo
    model with the body springs as tendons), and the largest relative difference of H and
    c + g to MuJoCo's at random states.

The machine is shared: the rates of ours and MuJoCo's are measured interleaved, the load
average is printed before and after, and S1/S2 are also given per CPU second (what an idle
core would give), next to the per-wall-second figure the targets define. The full run takes
about 1.5 min on a busy 2-core machine; ``--quick`` about 20 s.

Usage:  python scripts/bench_engine.py [--quick] [--no-s3] [--s1-only] [--json FILE]
        [--controllers pd_p,pd_pf,pd_pf+drive,pd_alpha]  (S1 of plug-in laws and the drive)
"""
from __future__ import annotations

import argparse
import inspect
import json
import os
import platform
import statistics
import sys
import time
from typing import Any, Callable

import host_speed

import numpy as np

try:
    import mujoco
    from mujoco import rollout as mj_rollout
except ImportError:  # S3 is then reported as not measured
    mujoco = None
    mj_rollout = None

import numba
from numba import njit

from hexapod_control.core.closed_loop import Case, run, run_batch, score_batch
from hexapod_sim.core import dynamics, engine
from hexapod_common.core import layout as L
from hexapod_common.core.params import N_LEGS, HexapodParams, load_params

#: S1 configurations (label, dt s, control period s, target x real time or None).
S1_CASES = (("10 kHz physics, 1 kHz control", 1e-4, 1e-3, 150.0),
            ("10 kHz physics, control every step", 1e-4, 1e-4, 60.0),
            ("paper experiments: 20 kHz physics, 10 kHz control", 5e-5, 1e-4, None))
S1_TARGET = 150.0    # x real time at 1 kHz control
S2_TARGET = 1000.0   # simulated s per wall s, both cores (issue 37)
S2_TARGET_ONE = 500.0  # the same on one thread
S3_TOL = 1e-9        # relative difference of H, c + g to MuJoCo's

_N_ACCEL_ARGS = len(inspect.signature(dynamics.leg_accel.py_func).parameters)
# Trailing leg_accel arguments beyond model.md's 16 (the optional implicit ground damping
# B_gx, B_gy, h of newer engines): zero, the plain explicit step of model.md.
_ACCEL_EXTRA = (0.0,) * (_N_ACCEL_ARGS - 16)


# -- machine ------------------------------------------------------------------------------
def machine() -> dict[str, Any]:
    """CPU model, cores, load and versions."""
    cpu = platform.processor() or "?"
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    try:
        usable = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        usable = os.cpu_count() or 1
    return {
        "cpu": cpu, "logical_cpus": os.cpu_count(), "usable_cpus": usable,
        "python": platform.python_version(), "numpy": np.__version__,
        "numba": numba.__version__, "numba_threads": numba.get_num_threads(),
        "mujoco": getattr(mujoco, "__version__", "not installed"),
        "platform": platform.platform(), "loadavg": os.getloadavg(),
    }


def _median(xs: list[float]) -> float:
    return float(statistics.median(xs))


def _timed(fn: Callable[[], Any]) -> float:
    t = time.perf_counter()
    fn()
    return time.perf_counter() - t


# -- S1 -----------------------------------------------------------------------------------
def bench_s1(p: HexapodParams, reps: int, controllers: tuple[str, ...] = ("pd_p", "pd_pf")
             ) -> dict[str, dict[str, list[float]]]:
    """Simulated s per wall s (the figure) and per CPU s of this thread (robust to other
    load on a shared machine) of run(p, controller), serial. A controller given as
    ``name+drive`` runs with ``<name>.force_loop = drive`` (PD-P&F's force loop in the
    drive); a plug-in (pd_alpha, module:Class) runs its Python law per tick."""
    out: dict[str, dict[str, list[float]]] = {}
    duration = p.run.duration
    base = p
    for label in controllers:
        c, _, mode = label.partition("+")
        p = base.with_values(**{f"{c}.force_loop": mode}) if mode else base
        run(p, c, duration=10 * p.sim.control_period)  # warm-up: load or compile
        r = run(p, c)
        if r.diverged_at is not None:
            raise RuntimeError(f"S1: base case diverged with {c} at t = {r.diverged_at} s")
        wall, cpu = [], []
        for _ in range(reps):
            t0, c0 = time.perf_counter(), time.thread_time()
            run(p, c)
            c1, t1 = time.thread_time(), time.perf_counter()
            wall.append(duration / (t1 - t0))
            cpu.append(duration / (c1 - c0))
        out[label] = {"wall": wall, "cpu": cpu}
    return out


# -- S2 -----------------------------------------------------------------------------------
def sweep_cases(p: HexapodParams, n_scales: int) -> list[Case]:
    """Ground sweep (all four ground parameters x scale) x both controllers."""
    scales = np.linspace(0.25, 2.0, n_scales)
    return [Case(p.with_values(**{"ground.scale": float(s)}), c)
            for c in ("pd_p", "pd_pf") for s in scales]


def bench_batch(cases: list[Case], duration: float, reps: int, score: bool = False
                ) -> dict[str, Any]:
    """Summed simulated s / wall s (and / CPU s of the process) of ``reps`` runs of
    run_batch over ``cases`` (recording the last cycle), after a two-case warm-up; with
    ``score``, of score_batch instead (the last cycle scored on the fly, as a sweep does)."""
    p = cases[0].params
    n = round(duration / p.sim.control_period)
    window = (n - round(p.cycle_time / p.sim.control_period), n)
    record_from = max(0.0, duration - p.cycle_time)
    run_batch(cases[:2], 10 * p.sim.control_period, 0.0)  # warm-up: load or compile
    if score:
        score_batch(cases[:2], duration, window)
    rates, cpu_rates, ok = [], [], 0
    for _ in range(reps):
        t, c = time.perf_counter(), time.process_time()
        res = (score_batch(cases, duration, window) if score
               else run_batch(cases, duration, record_from))
        cpu, wall = time.process_time() - c, time.perf_counter() - t
        sim = len(cases) * duration
        rates.append(sim / wall)
        cpu_rates.append(sim / cpu)
        ok = int(res.ok.sum())
    return {"cases": len(cases), "duration": duration, "ok": ok, "rates": rates,
            "cpu_rates": cpu_rates}


def bench_s2(p: HexapodParams, n_scales: int, duration: float, reps: int,
             one_thread: bool, recording: bool = False) -> dict[str, Any]:
    """:func:`bench_batch` (scoring) over S2's sweep (:func:`sweep_cases`); with
    ``one_thread`` also one repetition on a single numba thread (parallel scaling), with
    ``recording`` also ``reps`` recording the last cycle instead."""
    cases = sweep_cases(p, n_scales)
    out = bench_batch(cases, duration, reps, score=True)
    threads = numba.get_num_threads()
    single = None
    if one_thread and threads > 1:
        numba.set_num_threads(1)
        try:
            single = bench_batch(cases, duration, 1, score=True)["rates"][0]
        finally:
            numba.set_num_threads(threads)
    rec = bench_batch(cases, duration, reps)["rates"] if recording else None
    return {**out, "one_thread_rate": single, "threads": threads,
            "layer": numba.threading_layer(), "recording_rates": rec}


# -- S3 -----------------------------------------------------------------------------------
@njit(cache=False)
def one_leg_steps(q, dq, l1, l2, mh, mk, mf, grav, dt, extra, n):  # type: ignore[no-untyped-def]
    """n semi-implicit Euler steps of one free leg (no torque, no contact): our per-leg step,
    the model MuJoCo's one-leg model has."""
    for _ in range(n):
        a0, a1, a2, a3 = dynamics.leg_accel(q[2], q[3], dq[2], dq[3], l1, l2, mh, mk, mf, grav,
                                            0.0, 0.0, 0.0, 0.0, 0.0, 0.0, *extra)
        dq[0] += dt * a0
        dq[1] += dt * a1
        dq[2] += dt * a2
        dq[3] += dt * a3
        q[0] += dt * dq[0]
        q[1] += dt * dq[1]
        q[2] += dt * dq[2]
        q[3] += dt * dq[3]


def _leg_values(p: HexapodParams) -> tuple[float, float, float, float, float]:
    r = p.robot
    return r.leg_length_1, r.leg_length_2, r.body_mass / N_LEGS, r.mass_1, r.mass_2


Q_LEG = np.array([0.0, 1.8, 0.35, -0.7])
DQ_LEG = np.array([1.0, 0.0, 0.8, -1.5])


def check_one_leg(p: HexapodParams, n: int = 2000) -> float:
    """Relative state difference after n steps of our one-leg loop and MuJoCo's (sanity)."""
    from hexapod_sim import mujoco_model as mm
    q, dq = Q_LEG.copy(), DQ_LEG.copy()
    one_leg_steps(q, dq, *_leg_values(p), L.GRAVITY, p.sim.dt, _ACCEL_EXTRA, n)
    m = mm.build_leg_model(p)
    d = mujoco.MjData(m)
    mm.set_leg_state(m, d, Q_LEG, DQ_LEG)
    mujoco.mj_step(m, d, nstep=n)
    ours, theirs = np.concatenate([q, dq]), np.concatenate([d.qpos, d.qvel])
    return float(np.linalg.norm(ours - theirs) / np.linalg.norm(theirs))


def max_dynamics_error(n_states: int) -> dict[str, float]:
    """Largest norm-wise relative difference of H, c + g and unforced ddq to MuJoCo's, over
    random states of the base leg and a lopsided one (L1 != L2, M1 != M2)."""
    from hexapod_sim import mujoco_model as mm
    rng = np.random.default_rng(2003)
    worst = {"H": 0.0, "bias": 0.0, "ddq": 0.0}
    base = load_params()
    lopsided = base.with_values(**{"robot.leg_length_1": 0.9, "robot.leg_length_2": 1.25,
                                   "robot.mass_1": 2.5, "robot.mass_2": 0.7})
    for p in (base, lopsided):
        l1, l2, mh, mk, mf = _leg_values(p)
        m = mm.build_leg_model(p)
        d = mujoco.MjData(m)
        for _ in range(n_states):
            q = np.concatenate([rng.uniform(-5, 5, 2), rng.uniform(-np.pi, np.pi, 2)])
            dq = np.concatenate([rng.uniform(-3, 3, 2), rng.uniform(-20, 20, 2)])
            H_mj, b_mj = mm.mass_matrix_and_bias(m, d, q, dq)
            H = dynamics.mass_matrix(q, l1, l2, mh, mk, mf)
            b = dynamics.bias_forces(q, dq, l1, l2, mh, mk, mf, L.GRAVITY)
            a_mj = mm.leg_accel(m, d, q, dq)
            a = np.array(dynamics.leg_accel(q[2], q[3], dq[2], dq[3], l1, l2, mh, mk, mf,
                                            L.GRAVITY, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
                                            *_ACCEL_EXTRA))
            worst["H"] = max(worst["H"], float(np.linalg.norm(H - H_mj) / np.linalg.norm(H_mj)))
            worst["bias"] = max(worst["bias"],
                                float(np.linalg.norm(b - b_mj) / np.linalg.norm(b_mj)))
            worst["ddq"] = max(worst["ddq"],
                               float(np.linalg.norm(a - a_mj) / np.linalg.norm(a_mj)))
    return worst


def bench_s3(p: HexapodParams, reps: int, n_steps: int, n_py: int) -> dict[str, list[float]]:
    """Step rates (steps per wall second), each entry a list over interleaved repetitions."""
    from hexapod_sim import mujoco_model as mm
    rates: dict[str, list[float]] = {k: [] for k in (
        "ours_leg", "mj_leg_py", "mj_leg_nstep", "mj_leg_rollout",
        "ours_hex", "ours_hex_py", "mj_hex_py", "mj_hex_nstep")}
    leg = _leg_values(p)
    dt = p.sim.dt
    # Our six-leg engine: the real model (contacts, body springs) from the base initial state,
    # zero torque, in bursts short enough (0.2 s) that the collapsing robot never diverges.
    P = L.model_vector(p)
    s0 = engine.initial_state(p)
    torque = np.zeros((N_LEGS, 2))
    burst = 2000
    m_leg = mm.build_leg_model(p)
    d_leg = mujoco.MjData(m_leg)
    m_hex = mm.build_hexapod_model(p)
    d_hex = mujoco.MjData(m_hex)
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    x0 = np.empty(mujoco.mj_stateSize(m_leg, spec))

    def reset_leg() -> None:
        mm.set_leg_state(m_leg, d_leg, Q_LEG, DQ_LEG)

    def reset_hex() -> None:
        mm.set_leg_state(m_hex, d_hex, s0[L.Q0:L.Q0 + 24], s0[L.V0:L.V0 + 24])

    reset_leg()
    mujoco.mj_getState(m_leg, d_leg, x0, spec)
    out_state = np.empty((1, n_steps, x0.size))

    def ours_leg() -> None:
        one_leg_steps(Q_LEG.copy(), DQ_LEG.copy(), *leg, L.GRAVITY, dt, _ACCEL_EXTRA, n_steps)

    def ours_hex() -> None:
        for _ in range(n_steps // burst):
            s = s0.copy()
            if not engine.advance(s, torque, P, burst):
                raise RuntimeError("S3: six-leg burst diverged")

    def ours_hex_py() -> None:
        s = s0.copy()
        for _ in range(n_py):
            engine.advance(s, torque, P, 1)

    def mj_leg_py() -> None:
        reset_leg()
        step = mujoco.mj_step
        for _ in range(n_py):
            step(m_leg, d_leg)

    def mj_leg_nstep() -> None:
        reset_leg()
        mujoco.mj_step(m_leg, d_leg, nstep=n_steps)

    def mj_leg_rollout() -> None:
        mj_rollout.rollout(m_leg, d_leg, x0[None, :], nstep=n_steps, state=out_state)

    def mj_hex_py() -> None:
        reset_hex()
        step = mujoco.mj_step
        for _ in range(n_py):
            step(m_hex, d_hex)

    def mj_hex_nstep() -> None:
        reset_hex()
        mujoco.mj_step(m_hex, d_hex, nstep=n_steps)

    jobs = {"ours_leg": (ours_leg, n_steps), "mj_leg_py": (mj_leg_py, n_py),
            "mj_leg_nstep": (mj_leg_nstep, n_steps),
            "mj_leg_rollout": (mj_leg_rollout, n_steps),
            "ours_hex": (ours_hex, (n_steps // burst) * burst),
            "ours_hex_py": (ours_hex_py, n_py),
            "mj_hex_py": (mj_hex_py, n_py), "mj_hex_nstep": (mj_hex_nstep, n_steps)}
    for fn, _ in jobs.values():  # warm-up (compiles one_leg_steps, starts the rollout pool)
        fn()
    for _ in range(reps):  # interleaved: drifting load hits ours and MuJoCo's alike
        for name, (fn, n) in jobs.items():
            rates[name].append(n / _timed(fn))
    return rates


# -- report -------------------------------------------------------------------------------
def _row(rows: list[tuple[str, ...]], ident: str, what: str, target: str, measured: str,
         gap: str) -> None:
    rows.append((ident, what, target, measured, gap))


def _fmt_rate(x: float) -> str:
    return f"{x / 1e6:.2f} M/s" if x >= 1e6 else f"{x / 1e3:.0f} k/s"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="short run (~20 s), fewer repetitions")
    ap.add_argument("--json", metavar="FILE", help="also write every raw figure to FILE")
    ap.add_argument("--no-s3", action="store_true",
                    help="skip S3 (MuJoCo comparison): S1 and S2 only")
    ap.add_argument("--controllers", default="pd_p,pd_pf",
                    help="S1's controllers, comma-separated registered names; name+drive "
                    "puts the force loop in the drive (e.g. pd_p,pd_pf,pd_pf+drive,pd_alpha)")
    ap.add_argument("--s1-only", action="store_true", help="S1 only (no S2, S3)")
    args = ap.parse_args(argv)
    q = args.quick
    p = load_params()
    info = machine()
    print("machine: {cpu}, {logical_cpus} logical CPUs ({usable_cpus} usable), "
          "Python {python}, numpy {numpy}, numba {numba} ({numba_threads} threads), "
          "mujoco {mujoco}".format(**info))
    print(f"         {info['platform']}; load average before: "
          + " ".join(f"{x:.2f}" for x in info["loadavg"]) + f"; {host_speed.describe()}")
    integ = getattr(p.sim, "integrator", "semi_implicit_euler")
    print(f"base case: dt = {p.sim.dt:g} s, control period = {p.sim.control_period:g} s, "
          f"duration = {p.run.duration:g} s, integrator = {integ}")
    t_start = time.perf_counter()
    raw: dict[str, Any] = {"machine": info, "quick": q, "section_wall_s": {}}
    rows: list[tuple[str, ...]] = []

    def section(name: str, t0: float) -> None:
        raw["section_wall_s"][name] = time.perf_counter() - t0

    t0 = time.perf_counter()
    raw["s1"] = {}
    for label, dt, period, target in S1_CASES:
        s1 = bench_s1(p.with_values(**{"sim.dt": dt, "sim.control_period": period}),
                      reps=3 if q else 5, controllers=tuple(args.controllers.split(",")))
        raw["s1"][label] = s1
        for c, xs in s1.items():
            tgt = f">= {target:g}" if target else "-"
            for kind, name in (("wall", "wall"), ("cpu", "CPU of the thread")):
                m = _median(xs[kind])
                _row(rows, "S1", f"{label}: {c}, sim s / {name} s", tgt, f"{m:.1f}",
                     f"{m / target:.2f}" if target else "-")
    section("S1", t0)

    if not args.s1_only:
        t0 = time.perf_counter()
        s2 = bench_s2(p, n_scales=16 if q else 64, duration=3.0, reps=1 if q else 3,
                      one_thread=not q, recording=True)
        raw["s2"] = s2
        section("S2", t0)
        m = _median(s2["rates"])
        _row(rows, "S2", f"score_batch {s2['cases']} cases x {s2['duration']:g} s, sim s / wall "
             f"s ({s2['threads']} thr)", f">= {S2_TARGET:g}", f"{m:.0f}", f"{m / S2_TARGET:.2f}")
        m = _median(s2["cpu_rates"])
        _row(rows, "S2", "  same, sim s / CPU s of the process (per core)", f">= {S2_TARGET_ONE:g}",
             f"{m:.0f}", f"{m / S2_TARGET_ONE:.2f}")
        if s2["one_thread_rate"] is not None:
            m1 = s2["one_thread_rate"]
            _row(rows, "S2", "  same on 1 thread (parallel scaling)", f">= {S2_TARGET_ONE:g}",
                 f"{m1:.0f}", f"{m1 / S2_TARGET_ONE:.2f}")
        if s2["recording_rates"]:
            m = _median(s2["recording_rates"])
            _row(rows, "S2", "  same recording the last cycle (run_batch), sim s / wall s",
                 f">= {S2_TARGET:g}", f"{m:.0f}", f"{m / S2_TARGET:.2f}")

    if args.no_s3 or args.s1_only:
        _row(rows, "S3", "MuJoCo comparison", "-", "not measured: --no-s3", "-")
    elif mujoco is None:
        _row(rows, "S3", "MuJoCo comparison", "-", "not measured: mujoco not installed", "-")
    else:
        t0 = time.perf_counter()
        err = max_dynamics_error(50 if q else 200)
        raw["s3_error"] = err
        raw["s3_one_leg_trajectory_rel_diff"] = check_one_leg(p)
        s3 = bench_s3(p, reps=3 if q else 5, n_steps=100_000 if q else 200_000,
                      n_py=20_000 if q else 50_000)
        raw["s3"] = s3
        section("S3", t0)
        med = {k: _median(v) for k, v in s3.items()}
        for key, what in (("mj_leg_py", "mj_step, Python loop"),
                          ("mj_leg_nstep", "mj_step(nstep=N), C loop"),
                          ("mj_leg_rollout", "mujoco.rollout, 1 thread")):
            _row(rows, "S3", f"1 leg: ours (compiled loop) vs {what}",
                 f">= {_fmt_rate(med[key])}", _fmt_rate(med["ours_leg"]),
                 f"{med['ours_leg'] / med[key]:.1f}")
        for key, what in (("mj_hex_nstep", "6-leg MuJoCo mj_step(nstep=N)"),
                          ("mj_leg_py", "1-leg mj_step, Python loop")):
            _row(rows, "S3", f"6 legs: engine.advance vs {what}", f">= {_fmt_rate(med[key])}",
                 _fmt_rate(med["ours_hex"]), f"{med['ours_hex'] / med[key]:.1f}")
        _row(rows, "S3", "6 legs, Python loop: advance(n=1) vs mj_step",
             f">= {_fmt_rate(med['mj_hex_py'])}", _fmt_rate(med["ours_hex_py"]),
             f"{med['ours_hex_py'] / med['mj_hex_py']:.1f}")
        for k, what in (("H", "mass matrix H"), ("bias", "bias c + g"),
                        ("ddq", "unforced ddq")):
            _row(rows, "S3", f"max rel. diff. of {what} to MuJoCo", f"<= {S3_TOL:g}",
                 f"{err[k]:.1e}", "ok" if err[k] <= S3_TOL else "FAIL")
        _row(rows, "S3", "1 leg, 2000 steps: rel. state diff. to MuJoCo", "(round-off)",
             f"{raw['s3_one_leg_trajectory_rel_diff']:.1e}", "-")

    w = [max(len(r[i]) for r in rows + [("id", "what", "target", "measured", "gap")])
         for i in range(5)]
    print()
    header = ("id", "what", "target", "measured", "gap (meas/target)")
    print("  ".join(h.ljust(w[i]) for i, h in enumerate(header)))
    print("  ".join("-" * w[i] for i in range(4)) + "  " + "-" * len(header[4]))
    for r in rows:
        print("  ".join(r[i].ljust(w[i]) for i in range(5)))
    if "s3" in raw:
        med = {k: _median(v) for k, v in raw["s3"].items()}
        print("\nS3 step rates (median, steps / wall s): " + ", ".join(
            f"{k} {_fmt_rate(v)}" for k, v in med.items()))
        print("    ours_hex = engine.advance on the full model (contacts on, body springs, "
              "2000-step bursts); mj_hex = six legs + body-spring tendons, no contact")
    print("\nS1 samples (wall): " + "; ".join(
        f"{label} {c}: " + ", ".join(f"{x:.1f}" for x in xs["wall"])
        for label, s1 in raw["s1"].items() for c, xs in s1.items()))
    if "s2" in raw:
        print(f"S2 samples: {', '.join(f'{x:.0f}' for x in raw['s2']['rates'])} "
              f"({raw['s2']['ok']}/{raw['s2']['cases']} cases finished, threading layer "
              f"{raw['s2']['layer']}); recording: "
              f"{', '.join(f'{x:.0f}' for x in raw['s2']['recording_rates'] or [])}")
    print("section wall times incl. warm-up/compile: " + ", ".join(
        f"{k} {v:.0f} s" for k, v in raw["section_wall_s"].items()))
    raw["loadavg_after"] = os.getloadavg()
    print(f"load average after: {' '.join(f'{x:.2f}' for x in raw['loadavg_after'])}; "
          f"benchmark wall time {time.perf_counter() - t_start:.0f} s; "
          f"{host_speed.describe()}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(raw, fh, indent=1, default=float)
    return 0


if __name__ == "__main__":
    sys.exit(main())
