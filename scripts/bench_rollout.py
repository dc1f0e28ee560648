#!/usr/bin/env python3
"""S2 against MuJoCo: our batched engine and ``mujoco.rollout`` of the same six-leg model.

quality.md's S2 asks for >= 3x ``mujoco.rollout`` of the same six-leg model (contacts off)
on the same threads. Three figures, measured interleaved in one process, medians of
``--reps``, on ``--threads`` threads (numba's and the rollout's alike):

* ``ours, closed loop``: the S2 figure itself, ``closed_loop.run_batch`` over ``--cases``
  cases (ground sweep x both controllers, contacts on) at the params file's control rate
  and physics step, simulated s summed over cases per wall s;
* ``ours, physics only, ground off``: the batched engine's physics step
  (``batch_physics.block_prepare`` / ``block_solve`` / ``block_integrate``, the same blocks
  ``run_batch`` steps) of the same six-leg model with the ground gains zeroed (MuJoCo's
  model has no ground contact) and a constant torque, ``--cases`` states, ``--steps`` steps;
* ``mujoco.rollout``: the six-leg MuJoCo model of ``hexapod_sim.mujoco_model`` (body
  springs as tendons, no contacts, same dt, same semi-implicit Euler) from the same states,
  same torque, same number of steps, one ``MjData`` per thread, ``Rollout(nthread=...)``.

Each figure is simulated s per wall s (and per CPU s of the process); the ratios ours /
MuJoCo are printed with the load average. The two physics-only runs start from the same
states and are checked against each other (the models are the same: tests/
test_mujoco_equivalence.py), so the comparison is of like work.

Usage: python scripts/bench_rollout.py [--cases 128] [--steps 2000] [--reps 5] [--threads 2]
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from collections.abc import Callable
from typing import Any

import mujoco
import numba
import numpy as np
from hexapod_control.core.closed_loop import Case, run_batch
from hexapod_sim import mujoco_model as mm
from hexapod_sim.core import engine
from hexapod_common.core import layout as L
from hexapod_sim.core.batch_physics import (
    LANES,
    block_integrate,
    block_prepare,
    block_scratch,
    block_solve,
)
from hexapod_common.core.params import N_LEGS, load_params
from mujoco import rollout as mj_rollout
from numba import njit, prange

S2_TARGET_RATIO = 3.0  # ours >= 3x mujoco.rollout (quality.md S2)


@njit(cache=False, parallel=True)
def _step_blocks(Xs, PTs, TQ, counts, n_steps):  # type: ignore[no-untyped-def]
    """n_steps physics steps of every block (prange over blocks), torques TQ (12, LANES)."""
    for j in prange(Xs.shape[0]):
        FH, WK, FF, QDD, TR, FLAG = block_scratch()
        X, PT, n = Xs[j], PTs[j], counts[j]
        for _ in range(n_steps):
            block_prepare(X, PT, n, FH, WK, TR)
            block_solve(X, TQ, PT, n, FH, WK, FF, QDD, FLAG)
            block_integrate(X, PT, n, QDD)


def _states(p: Any, n: int, seed: int = 5) -> np.ndarray:
    """n states near the base initial state (seeded perturbations), (n, STATE_SIZE)."""
    rng = np.random.default_rng(seed)
    s0 = engine.initial_state(p)
    out = np.repeat(s0[None, :], n, axis=0)
    out[:, L.Q0:L.Q0 + 24] += rng.normal(0.0, 0.02, (n, 24))
    out[:, L.V0:L.V0 + 24] += rng.normal(0.0, 0.2, (n, 24))
    return out


def _blocks(states: np.ndarray, P: np.ndarray, threads: int
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """States and model vectors cut into blocks of at most LANES columns (two per thread
    where there are cases enough, as run_batch plans them)."""
    n = states.shape[0]
    per = min(LANES, max(8, -(-n // (2 * threads))))
    nb = -(-n // per)
    Xs = np.zeros((nb, states.shape[1], LANES))
    PTs = np.zeros((nb, P.size, LANES))
    counts = np.zeros(nb, dtype=np.int64)
    for j in range(nb):
        part = states[j * per:(j + 1) * per]
        counts[j] = part.shape[0]
        Xs[j, :, :part.shape[0]] = part.T
        PTs[j] = P[:, None]
    return Xs, PTs, counts


def _timed(fn: Callable[[], Any]) -> tuple[float, float]:
    t, c = time.perf_counter(), time.process_time()
    fn()
    return time.perf_counter() - t, time.process_time() - c


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=128)
    ap.add_argument("--steps", type=int, default=2000, help="physics steps per case (physics only)")
    ap.add_argument("--duration", type=float, default=3.0, help="closed loop: s per case")
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args(argv)
    numba.set_num_threads(min(args.threads, numba.config.NUMBA_NUM_THREADS))
    p = load_params().with_values(**{"sim.integrator": "semi_implicit_euler"})
    dt = p.sim.dt
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.2f}; "
          f"{args.threads} threads (numba {numba.get_num_threads()}); dt {dt:g} s, control "
          f"{1 / p.sim.control_period:g} Hz; mujoco {mujoco.__version__}", flush=True)

    # Closed loop (the S2 figure): ground sweep x both controllers, contacts on.
    p_loop = load_params()
    scales = np.linspace(0.25, 2.0, max(1, args.cases // 2))
    cases = [Case(p_loop.with_values(**{"ground.scale": float(s)}), c)
             for c in ("pd_p", "pd_pf") for s in scales][:args.cases]
    record_from = max(0.0, args.duration - p_loop.cycle_time)
    run_batch(cases[:2], 10 * p_loop.sim.control_period, 0.0)  # warm-up

    # Physics only, ground off: the same six-leg model as MuJoCo's.
    P = L.model_vector(p)
    P[[L.P_KGX, L.P_KGY, L.P_BGX, L.P_BGY]] = 0.0
    states = _states(p, args.cases)
    torque = np.random.default_rng(7).uniform(-50.0, 50.0, (N_LEGS, 2))
    TQ = np.repeat(torque.reshape(12, 1), LANES, axis=1)
    Xs0, PTs, counts = _blocks(states, P, args.threads)
    Xs = Xs0.copy()

    model = mm.build_hexapod_model(p)
    datas = [mujoco.MjData(model) for _ in range(args.threads)]
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    nstate = mujoco.mj_stateSize(model, spec)
    x0 = np.empty((args.cases, nstate))
    d = datas[0]
    for b in range(args.cases):
        mm.set_leg_state(model, d, states[b, L.Q0:L.Q0 + 24], states[b, L.V0:L.V0 + 24])
        mujoco.mj_getState(model, d, x0[b], spec)
    ctrl = np.repeat(torque.reshape(1, 1, 12), args.cases, axis=0)
    ctrl = np.repeat(ctrl, args.steps, axis=1)
    out_state = np.empty((args.cases, args.steps, nstate))
    pool = mj_rollout.Rollout(nthread=args.threads)

    def ours_loop() -> None:
        run_batch(cases, args.duration, record_from)

    def ours_physics() -> None:
        Xs[:] = Xs0
        _step_blocks(Xs, PTs, TQ, counts, args.steps)

    def mj() -> None:
        pool.rollout([model] * args.cases, datas, x0, ctrl, nstep=args.steps, state=out_state)

    ours_physics()
    mj()
    # The same model and states: the two physics-only runs agree (to round-off growth).
    ours_q = np.concatenate([Xs[j, L.Q0:L.Q0 + 24, :counts[j]].T for j in range(len(counts))])
    qpos = out_state[:, -1, 1:1 + 24]  # FULLPHYSICS: time, qpos, qvel, ...
    rel = float(np.max(np.abs(ours_q - qpos)) / np.max(np.abs(qpos)))
    print(f"physics only: max rel. difference of q after {args.steps} steps, ours vs MuJoCo: "
          f"{rel:.2g}", flush=True)
    print(f"numba threading layer: {numba.threading_layer()}", flush=True)

    sim_loop = len(cases) * args.duration
    sim_phys = args.cases * args.steps * dt
    rows: dict[str, list[tuple[float, float]]] = {"loop": [], "phys": [], "mj": []}
    loads = []
    for _ in range(args.reps):  # interleaved: drifting load hits all three alike
        loads.append(os.getloadavg()[0])
        for key, fn, sim in (("loop", ours_loop, sim_loop), ("phys", ours_physics, sim_phys),
                             ("mj", mj, sim_phys)):
            wall, cpu = _timed(fn)
            rows[key].append((sim / wall, sim / cpu))
    pool.close()

    def med(key: str, i: int) -> float:
        return statistics.median(r[i] for r in rows[key])

    print(f"S2 vs mujoco.rollout, {args.cases} cases, {args.threads} threads, medians of "
          f"{args.reps} (load average {min(loads):.1f}-{max(loads):.1f}):")
    print(f"  {'what':52s} {'sim s/wall s':>12s} {'sim s/CPU s':>12s}")
    for key, what in (("loop", f"ours, closed loop (run_batch, contacts, {args.duration:g} s)"),
                      ("phys", "ours, physics only, ground off"),
                      ("mj", "mujoco.rollout, six-leg model, no contacts")):
        print(f"  {what:52s} {med(key, 0):12.1f} {med(key, 1):12.1f}")
    for key, what in (("loop", "closed loop"), ("phys", "physics only")):
        r_wall = med(key, 0) / med("mj", 0)
        print(f"  ratio ours ({what}) / mujoco.rollout: {r_wall:.2f}x wall, "
              f"{med(key, 1) / med('mj', 1):.2f}x CPU (target >= {S2_TARGET_RATIO:g}x; "
              f"gap {r_wall / S2_TARGET_RATIO:.2f})")
    print("samples (wall): " + "; ".join(
        f"{k}: {', '.join(f'{r[0]:.0f}' for r in v)}" for k, v in rows.items()))
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
