"""The closed loop of many cases at once: blocks of cases in structure-of-arrays layout.

Each block holds cases of one physics step count per tick (``substeps``) as columns of
hexapod_sim.core.batch_physics arrays and runs closed_loop.run_ticks's tick for all of them:
observe (state part shared with the first physics step), control law, saturation,
``substeps`` physics steps. Columns of code PD_PF_DRIVE (PD-P&F with its force loop in the
drive) get their torque at every physics step from the drive law instead
(hexapod_sim.core.drive, same arithmetic), with the foot force at the step's start under
the previous step's torque. Each case's evaluation window is recorded sample by sample or
scored on the fly (hexapod_common.core.index_sums, the sums the analysis adds up too). A case
that diverges leaves its block at once (its column is
swapped behind the active ones), so it costs the others nothing. Blocks run in parallel
(numba ``prange``, one block per thread at a time).
"""
from __future__ import annotations

import numpy as np
from hexapod_common.core.jit import njit, prange

from hexapod_sim.core.actuator import clip_torque
from hexapod_sim.core.batch_physics import (LANES, block_integrate, block_prepare, block_sample,
                                            block_scratch, block_solve, swap_columns)
from hexapod_sim.core.engine import state_ok
from hexapod_common.core.kinematics import foot_force_torque
from hexapod_common.core.index_sums import add_sample, start_window
from hexapod_common.core.layout import (O_FP, O_HF, O_HP, O_THV, O_TQ, P_DT, P_L1, P_L2,
                                        P_TMAX, Q0, V0)
from hexapod_common.core.params import N_LEGS

from .controllers import PD_PF_DRIVE, leg_demand

#: Most cases per block: the block arrays' width (their work arrays stay in a core's L2).
MAX_BLOCK = LANES


@njit(cache=True)
def _drop(X, PT, TQ, G, codes, cols, b, last):  # type: ignore[no-untyped-def]
    """Swap column b behind the active ones (into column ``last``)."""
    swap_columns(X, b, last)
    swap_columns(PT, b, last)
    swap_columns(TQ, b, last)
    swap_columns(G, b, last)
    codes[b], codes[last] = codes[last], codes[b]
    cols[b], cols[last] = cols[last], cols[b]


@njit(cache=True)
def drive_columns(X, PT, G, codes, n, TQ, FF, theta_d, theta_vel_d, step):  # type: ignore[no-untyped-def]
    """PD-P&F's drive law at physics step ``step`` of the tick for the PD_PF_DRIVE columns:
    kp = K_f Kp, kd = K_f Kd, k_force = K_f, setpoints the tick's references theta_d,
    theta_vel_d (6, 2); FF the foot force at the step's start; writes the saturated torque
    into TQ."""
    for b in range(n):
        if codes[b] != PD_PF_DRIVE:
            continue
        kf = G[4, b]
        el = step * PT[P_DT, b]
        for i in range(N_LEGS):
            th1, th2 = X[Q0 + 4 * i + 2, b], X[Q0 + 4 * i + 3, b]
            tau1, tau2 = 0.0, 0.0
            if kf != 0.0:
                tau1, tau2 = foot_force_torque(th1, th2, FF[2 * i, b], FF[2 * i + 1, b],
                                               PT[P_L1, b], PT[P_L2, b])
            for j in range(2):
                q = th1 if j == 0 else th2
                dq = X[V0 + 4 * i + 2 + j, b]
                tau = tau1 if j == 0 else tau2
                kp, kd = kf * G[2 * j, b], kf * G[2 * j + 1, b]
                qr, dqr = theta_d[i, j], theta_vel_d[i, j]
                v = kp * (qr + dqr * el - q) + kd * (dqr - dq) + 0.0 - kf * tau
                TQ[2 * i + j, b] = clip_torque(v, PT[P_TMAX, b])


@njit(cache=True)
def _all_finite(a):  # type: ignore[no-untyped-def]
    """True if every value of the contiguous array ``a`` is finite (no temporary array)."""
    for v in a.flat:
        if not np.isfinite(v):
            return False
    return True


@njit(cache=True, error_model="numpy")
def run_block(X, PT, codes, G, n, theta_d, theta_vel_d, substeps, rec_offset,  # type: ignore[no-untyped-def]
              obs_out, cols, ok, score_end, hip_ref, foot_ref, acc_out, finite):
    """Run columns 0..n-1 of a block for len(theta_d) ticks from torque zero.

    X (STATE_SIZE, B) states, PT (MODEL_SIZE, B) model vectors, codes (B,) controller codes,
    G (5, B) gains, cols (B,) the case index of each column; B = batch_physics.LANES.
    Records the sample of tick k
    into obs_out[case, k - rec_offset] when that row exists (the tick after the last too),
    and sets ok[case]. Scores ticks rec_offset..score_end (none if score_end < rec_offset)
    into acc_out[case, w] (cases, W, index_sums.ACC_SIZE): W consecutive windows of
    (score_end - rec_offset) / W ticks each (index_sums: row rec_offset + w M starts window w
    and is also the last sample of window w - 1; the samples are added against the
    references hip_ref[k], foot_ref[k] (6, 2)) and clears finite[case] if any value of a
    scored sample is not finite.
    """
    FH, WK, FF, QDD, TR, FLAG = block_scratch()
    windows = acc_out.shape[1]
    window = max(1, (score_end - rec_offset) // max(1, windows))
    sample = np.empty((9, N_LEGS, 2))
    TQ = np.zeros((2 * N_LEGS, LANES))
    n_ticks = theta_d.shape[0]
    n_rec = obs_out.shape[1]
    any_drive = False
    for b in range(n):
        if codes[b] == PD_PF_DRIVE:
            any_drive = True
    for k in range(n_ticks + 1):
        block_prepare(X, PT, n, FH, WK, TR)
        block_solve(X, TQ, PT, n, FH, WK, FF, QDD, FLAG)
        r = k - rec_offset
        if 0 <= r < n_rec:
            for b in range(n):
                block_sample(X, TQ, PT, b, FH, WK, FF, QDD, obs_out[cols[b], r])
        if rec_offset <= k <= score_end:
            w = (k - rec_offset) // window
            at = k - rec_offset - w * window
            for b in range(n):
                c = cols[b]
                block_sample(X, TQ, PT, b, FH, WK, FF, QDD, sample)
                if at == 0 and w > 0:  # the last sample of window w - 1 ...
                    add_sample(acc_out[c, w - 1], sample[O_TQ], sample[O_THV], sample[O_HF],
                               sample[O_HP], hip_ref[k], sample[O_FP], foot_ref[k])
                if at == 0 and w < windows:  # ... is row 0 of window w
                    start_window(acc_out[c, w], sample[O_HP], hip_ref[k], sample[O_FP],
                                 foot_ref[k])
                elif at != 0:
                    add_sample(acc_out[c, w], sample[O_TQ], sample[O_THV], sample[O_HF],
                               sample[O_HP], hip_ref[k], sample[O_FP], foot_ref[k])
                if not _all_finite(sample):
                    finite[c] = False
        if k == n_ticks:
            break
        for i in range(N_LEGS):
            thd1, thd2 = theta_d[k, i, 0], theta_d[k, i, 1]
            wd1, wd2 = theta_vel_d[k, i, 0], theta_vel_d[k, i, 1]
            for b in range(n):
                if codes[b] == PD_PF_DRIVE:
                    continue  # the drive sets its torque at every physics step
                t1, t2 = leg_demand(codes[b], G[0, b], G[1, b], G[2, b], G[3, b], G[4, b],
                                    X[Q0 + 4 * i + 2, b], X[Q0 + 4 * i + 3, b],
                                    X[V0 + 4 * i + 2, b], X[V0 + 4 * i + 3, b],
                                    FF[2 * i, b], FF[2 * i + 1, b], thd1, thd2, wd1, wd2,
                                    PT[P_L1, b], PT[P_L2, b])
                TQ[2 * i, b] = clip_torque(t1, PT[P_TMAX, b])
                TQ[2 * i + 1, b] = clip_torque(t2, PT[P_TMAX, b])
        for step in range(substeps):
            if step > 0:
                block_prepare(X, PT, n, FH, WK, TR)
                if any_drive:  # the foot force at this step's start under the last torque
                    block_solve(X, TQ, PT, n, FH, WK, FF, QDD, FLAG)
            if any_drive:
                drive_columns(X, PT, G, codes, n, TQ, FF, theta_d[k], theta_vel_d[k], step)
            block_solve(X, TQ, PT, n, FH, WK, FF, QDD, FLAG)
            block_integrate(X, PT, n, QDD)
        b = 0
        while b < n:
            if state_ok(X[:, b]):
                b += 1
            else:
                ok[cols[b]] = False
                n -= 1
                _drop(X, PT, TQ, G, codes, cols, b, n)
        if n == 0:
            return
    for b in range(n):
        ok[cols[b]] = True


@njit(cache=True, parallel=True)
def run_blocks(Xs, PTs, codes, Gs, counts, theta_d, theta_vel_d, substeps, rec_offset,  # type: ignore[no-untyped-def]
               obs_out, cols, ok, score_end, hip_ref, foot_ref, acc_out, finite):
    """:func:`run_block` for every block (leading axis of Xs, PTs, codes, Gs, cols; counts
    and substeps per block), in parallel."""
    for j in prange(Xs.shape[0]):
        run_block(Xs[j], PTs[j], codes[j], Gs[j], counts[j], theta_d, theta_vel_d,
                  substeps[j], rec_offset, obs_out, cols[j], ok, score_end, hip_ref,
                  foot_ref, acc_out, finite)


def block_plan(substeps: np.ndarray, threads: int) -> list[np.ndarray]:
    """Case indices of each block: cases grouped by substeps, each group cut into blocks of
    at most :data:`MAX_BLOCK` cases and at least two blocks per thread where it has cases
    enough (8 or more per block)."""
    blocks = []
    for s in np.unique(substeps):
        idx = np.flatnonzero(substeps == s)
        per = max(8, -(-idx.size // (2 * threads)))
        per = min(per, MAX_BLOCK)
        blocks += [idx[a:a + per] for a in range(0, idx.size, per)]
    return blocks


__all__ = ["MAX_BLOCK", "block_plan", "drive_columns", "run_block", "run_blocks"]
