"""The physics engine: state, one integration step, observation at a control tick.

[resolution, model.md "Time integration"] Semi-implicit Euler at dt (default 1e-4 s):
dq += dt ddq, then q += dt dq; the contact state is updated every step. The joint torques
are held constant between control ticks (zero-order hold) by the caller.

[departure, sim.integrator] With the paper's ground (B_gy = 1e4 N s/m on a 1 kg foot) the
contact's damping time constant m/B = 1e-4 s equals dt, which explicit damping cannot resolve:
PD-P&F's indices then move by ~8 % between dt and dt/2. The default integrator,
``implicit_ground_damping``, evaluates the ground dampers at the end-of-step velocity
(a linearly implicit step per leg: (H + dt J_F^T B J_F) ddq = rhs), which keeps the base-case
indices within 1 % of a dt/2 run (tests/test_engine.py). ``semi_implicit_euler`` keeps
model.md's scheme as written.

Observation convention (used by the engine, the sim node and the analysis alike): the sample
at tick k holds the state at t_k and the torque *acting at that instant*, i.e. the held torque
T_{k-1} applied over (t_{k-1}, t_k]; the hip force f_i is evaluated at the same state with the
same torque. Index sums pair them over the window's samples 1..N (see indices.py).

Drive commands (model.md "Drive interface"): drive.py holds a command per joint and
evaluates it at every physics step with these same prepare/solve steps; its measured
foot-force torque is that of F_RF at the step's start state under the previous step's
torque (no algebraic loop; at a tick, the observation's foot force). Torque-only commands
reproduce the held-torque numbers of :func:`advance_prepared` bit for bit.

Speed: a compiled call takes an atomic reference on each array argument and a view of an
array is one more; those atomics were ~40 % of a physics step (perf). So the per-step
helpers (:func:`prepare`, :func:`solve`, :func:`leg_contact_solve`, :func:`euler_step`,
body.body_forces) are inlined into their callers (numba ``inline="always"``; they do no
division, so the callers' error model changes nothing) and read the state vector by index
rather than through :func:`legs` or slices; scalar helpers (dynamics.py, contact.py) are
free to call. docs/benchmarks.md, S1 and S3.
"""
from __future__ import annotations

import numpy as np
from hexapod_common.core.jit import njit

from .body import body_forces
from .contact import limit_force, spring_damper, update_contact
from .dynamics import leg_accel_cs, leg_solve, leg_system_cs
from .sincos import cos_sin
from .uneven_ground import ground_factors, note_touchdown
from hexapod_common.core.gait import reference
from hexapod_common.core.kinematics import foot_offset_cs, foot_velocity_cs
from hexapod_common.core.layout import (C0, OBS_FIELDS, P_BGX, P_BGY, P_DT, P_G, P_IMPL, P_KGX,
                                        P_KGY, P_L1, P_L2, P_MF, P_MH, P_MK, P_MU, Q0, STATE_SIZE,
                                        V0, X0)
from hexapod_common.core.params import N_LEGS, HexapodParams


@njit(cache=True)
def legs(s):  # type: ignore[no-untyped-def]
    """Views (q, dq) of shape (6, 4) into a state vector (layout.py: Q0, V0)."""
    return s[Q0:Q0 + 24].reshape(N_LEGS, 4), s[V0:V0 + 24].reshape(N_LEGS, 4)


#: A state is diverged when non-finite or beyond these magnitudes (m or rad, m/s or rad/s).
MAX_COORD = 1e4
MAX_RATE = 1e4


#: Per-leg columns of the engine's work array (the state part of a step, see :func:`prepare`).
W_FACTOR, W_BIAS, W_JAC, W_FG, W_CS, W_W = 0, 10, 14, 18, 20, 24
W_SIZE = 26


@njit(cache=True)
def scratch():  # type: ignore[no-untyped-def]
    """Work arrays of one state: (fh (6, 2), work (6, W_SIZE), ff (6, 2), qdd (6, 4))."""
    return (np.empty((N_LEGS, 2)), np.empty((N_LEGS, W_SIZE)), np.empty((N_LEGS, 2)),
            np.empty((N_LEGS, 4)))


@njit(cache=True, error_model="numpy", inline="always")
def prepare(s, P, fh, work):  # type: ignore[no-untyped-def]
    """The state part of the forces and accelerations at state ``s`` (no torque needed).

    Updates the contact state stored in ``s`` (idempotent for one state), writes F_RH into
    fh (6, 2) and, per leg, into ``work`` (6, W_SIZE): the factored system matrix, bias and
    foot Jacobian (dynamics.leg_system_cs), the ground force at the current velocity
    (0 in flight), cos/sin of theta1 and theta1 + theta2, and the joint rates.
    :func:`solve` finishes the step for a given torque; the observation of a tick and the
    first physics step after it share one call.
    """
    l1, l2 = P[P_L1], P[P_L2]
    h = P[P_DT] if P[P_IMPL] != 0.0 else 0.0
    body_forces(s, P, fh)
    for i in range(N_LEGS):
        qi, vi = Q0 + 4 * i, V0 + 4 * i  # leg i's (x_H, y_H, theta1, theta2) and rates
        th1, th12, w1, w2 = s[qi + 2], s[qi + 2] + s[qi + 3], s[vi + 2], s[vi + 3]
        c1, s1 = cos_sin(th1)
        c12, s12 = cos_sin(th12)
        dx, dy = foot_offset_cs(c1, s1, c12, s12, l1, l2)
        x, y = s[qi] + dx, s[qi + 1] + dy
        c, xt = update_contact(x, y, s[C0 + i], s[X0 + i])
        note_touchdown(s, i, s[C0 + i], c)
        s[C0 + i] = c
        s[X0 + i] = xt
        if c != 0.0:
            dvx, dvy = foot_velocity_cs(c1, s1, c12, s12, w1, w2, l1, l2)
            vx, vy = s[vi] + dvx, s[vi + 1] + dvy
            gx, gy = ground_factors(s, i)  # 1.0 on uniform ground (uneven_ground.py)
            bx, by = P[P_BGX] * gx, P[P_BGY] * gy
            fx, fy = spring_damper(x, y, vx, vy, xt, P[P_KGX] * gx, P[P_KGY] * gy, bx, by)
            factor, bias, jac = leg_system_cs(c1, s1, c12, s12, w1, w2, l1, l2, P[P_MH],
                                              P[P_MK], P[P_MF], P[P_G], bx, by, h)
        else:
            fx, fy = 0.0, 0.0
            factor, bias, jac = leg_system_cs(c1, s1, c12, s12, w1, w2, l1, l2, P[P_MH],
                                              P[P_MK], P[P_MF], P[P_G], 0.0, 0.0, 0.0)
        for k in range(10):
            work[i, W_FACTOR + k] = factor[k]
        for k in range(4):
            work[i, W_BIAS + k] = bias[k]
            work[i, W_JAC + k] = jac[k]
        work[i, W_FG], work[i, W_FG + 1] = fx, fy
        work[i, W_CS], work[i, W_CS + 1], work[i, W_CS + 2], work[i, W_CS + 3] = c1, s1, c12, s12
        work[i, W_W], work[i, W_W + 1] = w1, w2


@njit(cache=True, error_model="numpy", inline="always")
def leg_contact_solve(factor, bias, jac, c1, s1, c12, s12, w1, w2, P,  # type: ignore[no-untyped-def]
                      tm1, tm2, fhx, fhy, fx, fy, h, bx, by):
    """Accelerations of a leg whose foot is in contact, and the ground force it feels.

    factor, bias, jac: the leg's state part (dynamics.leg_system_cs, with the ground damping
    over h); c1, s1, c12, s12: cos/sin of theta1 and theta1 + theta2; (fx, fy): the ground
    force at the current velocity (N); (bx, by): the ground dampers at this foot (N s/m,
    uneven_ground.py). The damping terms act at the velocity at the end of the step of
    length h (h = 0: the current velocity, i.e. plain semi-implicit Euler). The
    force is then limited ("the ground never pulls"; Coulomb if mu > 0) and, if a limit
    applies, the leg is solved again with the limited force held fixed.
    Returns (ddx_H, ddy_H, ddth1, ddth2, F_x, F_y).
    """
    a0, a1, a2, a3 = leg_solve(factor, bias, jac, tm1, tm2, fhx, fhy, fx, fy)
    if h > 0.0:
        # end-of-step foot velocity change: J_F ddq h
        af, bf, ja2, jb2 = jac
        dvx = h * (a0 + af * a2 + ja2 * a3)
        dvy = h * (a1 + bf * a2 + jb2 * a3)
        fx -= bx * dvx
        fy -= by * dvy
    lx, ly = limit_force(fx, fy, P[P_MU])
    if lx != fx or ly != fy:
        a0, a1, a2, a3 = leg_accel_cs(c1, s1, c12, s12, w1, w2, P[P_L1], P[P_L2], P[P_MH],
                                      P[P_MK], P[P_MF], P[P_G], tm1, tm2, fhx, fhy, lx, ly,
                                      0.0, 0.0, 0.0)
    return a0, a1, a2, a3, lx, ly


@njit(cache=True, error_model="numpy", inline="always")
def solve(s, torque, P, fh, work, ff, qdd):  # type: ignore[no-untyped-def]
    """The torque part: from :func:`prepare`'s fh and work at state ``s`` and joint torques
    ``torque`` (6, 2) (N m), write F_RF into ff (6, 2) and ddq into qdd (6, 4)."""
    h = P[P_DT] if P[P_IMPL] != 0.0 else 0.0
    for i in range(N_LEGS):
        w = work[i]
        factor = (w[0], w[1], w[2], w[3], w[4], w[5], w[6], w[7], w[8], w[9])
        bias = (w[W_BIAS], w[W_BIAS + 1], w[W_BIAS + 2], w[W_BIAS + 3])
        jac = (w[W_JAC], w[W_JAC + 1], w[W_JAC + 2], w[W_JAC + 3])
        if s[C0 + i] != 0.0:
            gx, gy = ground_factors(s, i)
            a0, a1, a2, a3, fx, fy = leg_contact_solve(
                factor, bias, jac, w[W_CS], w[W_CS + 1], w[W_CS + 2], w[W_CS + 3], w[W_W],
                w[W_W + 1], P, torque[i, 0], torque[i, 1], fh[i, 0], fh[i, 1], w[W_FG],
                w[W_FG + 1], h, P[P_BGX] * gx, P[P_BGY] * gy)
        else:
            fx, fy = 0.0, 0.0
            a0, a1, a2, a3 = leg_solve(factor, bias, jac, torque[i, 0], torque[i, 1],
                                       fh[i, 0], fh[i, 1], 0.0, 0.0)
        ff[i, 0] = fx
        ff[i, 1] = fy
        qdd[i, 0] = a0
        qdd[i, 1] = a1
        qdd[i, 2] = a2
        qdd[i, 3] = a3


@njit(cache=True)
def accelerations(s, torque, P, fh, ff, qdd):  # type: ignore[no-untyped-def]
    """Forces and accelerations at state ``s`` under joint torques ``torque`` (6, 2) (N m).

    Updates the contact state stored in ``s`` (idempotent for one state) and writes
    F_RH into fh (6, 2), F_RF into ff (6, 2) and ddq into qdd (6, 4): :func:`prepare`
    then :func:`solve`.
    """
    work = np.empty((N_LEGS, W_SIZE))
    prepare(s, P, fh, work)
    solve(s, torque, P, fh, work, ff, qdd)


@njit(cache=True, inline="always")
def euler_step(s, qdd, dt):  # type: ignore[no-untyped-def]
    """The explicit Euler update of one physics step, in place: dq += dt ddq, then
    q += dt dq (the new dq); ``qdd`` (6, 4) from :func:`solve`, ``dt`` (s)."""
    for i in range(N_LEGS):
        for j in range(4):
            v = s[V0 + 4 * i + j] + dt * qdd[i, j]
            s[V0 + 4 * i + j] = v
            s[Q0 + 4 * i + j] += dt * v


@njit(cache=True)
def advance_prepared(s, torque, P, n_steps, fh, work, ff, qdd):  # type: ignore[no-untyped-def]
    """Integrate ``n_steps`` physics steps of P[P_DT] under the held ``torque`` (6, 2), in place,
    the first from fh/work that :func:`prepare` (or :func:`observe_prepared`) filled at the
    current state ``s`` with the same ``P``; the arrays are the step's scratch.

    Returns False (and stops) as soon as the state diverges.
    """
    dt = P[P_DT]
    for k in range(n_steps):
        if k > 0:
            prepare(s, P, fh, work)
        solve(s, torque, P, fh, work, ff, qdd)
        euler_step(s, qdd, dt)
    return state_ok(s)


@njit(cache=True)
def advance(s, torque, P, n_steps):  # type: ignore[no-untyped-def]
    """Integrate ``n_steps`` physics steps of P[P_DT] under the held ``torque`` (6, 2), in place.

    Returns False (and stops) as soon as the state diverges.
    """
    fh, work, ff, qdd = scratch()
    if n_steps > 0:
        prepare(s, P, fh, work)
    return advance_prepared(s, torque, P, n_steps, fh, work, ff, qdd)


@njit(cache=True)
def state_ok(s):  # type: ignore[no-untyped-def]
    """True while the state is finite and within :data:`MAX_COORD` / :data:`MAX_RATE`."""
    for k in range(24):
        a = s[Q0 + k]
        v = s[V0 + k]
        if not (abs(a) < MAX_COORD and abs(v) < MAX_RATE):  # also false for NaN
            return False
    return True


#: The fields :func:`leg_sample` returns, two values (x/joint 1, y/joint 2) each.
SAMPLE_ORDER = ("theta", "theta_vel", "torque", "foot_pos", "foot_vel", "foot_force",
                "hip_pos", "hip_vel", "hip_force")
if SAMPLE_ORDER != OBS_FIELDS:  # pragma: no cover - a layout change must update leg_sample
    raise ImportError("engine.leg_sample no longer matches layout.OBS_FIELDS")


@njit(cache=True, forceinline=True)
def leg_sample(xh, yh, th1, th2, vxh, vyh, w1, w2, c1, s1, c12, s12,  # type: ignore[no-untyped-def]
               tq1, tq2, ffx, ffy, ddxh, ddyh, fhx, fhy, l1, l2, mh, grav):
    """One leg's observation, the 18 values of obs[:, i, :] in OBS_FIELDS order.

    Hip (xh, yh) (m) and joint angles (rad), their rates, cos/sin of theta1 and
    theta1 + theta2, the torque acting (N m), the ground force F_RF, the hip accelerations
    (m/s^2) and the body force F_RH (N) at that state. The order is :data:`SAMPLE_ORDER`.
    """
    dx, dy = foot_offset_cs(c1, s1, c12, s12, l1, l2)
    dvx, dvy = foot_velocity_cs(c1, s1, c12, s12, w1, w2, l1, l2)
    # f_i = m_H (ddp_H - [0, -g]) - F_RH,i: the force leg i exerts on its body segment.
    return (th1, th2, w1, w2, tq1, tq2, xh + dx, yh + dy, vxh + dvx, vyh + dvy, ffx, ffy,
            xh, yh, vxh, vyh, mh * ddxh - fhx, mh * (ddyh + grav) - fhy)


@njit(cache=True)
def observe_prepared(s, torque_held, P, obs, fh, work, ff, qdd):  # type: ignore[no-untyped-def]
    """Fill ``obs`` (9, 6, 2) with the sample of the current tick (see module docstring) and
    leave the state part of state ``s`` in fh/work for :func:`advance_prepared`."""
    prepare(s, P, fh, work)
    solve(s, torque_held, P, fh, work, ff, qdd)
    l1, l2, mh, grav = P[P_L1], P[P_L2], P[P_MH], P[P_G]
    for i in range(N_LEGS):
        w = work[i]
        sample = leg_sample(s[Q0 + 4 * i], s[Q0 + 4 * i + 1], s[Q0 + 4 * i + 2],
                            s[Q0 + 4 * i + 3], s[V0 + 4 * i], s[V0 + 4 * i + 1],
                            s[V0 + 4 * i + 2], s[V0 + 4 * i + 3], w[W_CS], w[W_CS + 1],
                            w[W_CS + 2], w[W_CS + 3], torque_held[i, 0], torque_held[i, 1],
                            ff[i, 0], ff[i, 1], qdd[i, 0], qdd[i, 1], fh[i, 0], fh[i, 1], l1,
                            l2, mh, grav)
        for f in range(9):
            obs[f, i, 0] = sample[2 * f]
            obs[f, i, 1] = sample[2 * f + 1]


@njit(cache=True)
def observe(s, torque_held, P, obs):  # type: ignore[no-untyped-def]
    """Fill ``obs`` (9, 6, 2) with the sample of the current tick (see module docstring)."""
    fh, work, ff, qdd = scratch()
    observe_prepared(s, torque_held, P, obs, fh, work, ff, qdd)


def initial_state(p: HexapodParams) -> np.ndarray:
    """Hips at p_Hd(0) moving at [V_F, 0], joints at theta_d(0) moving at dtheta_d(0),
    no stored contacts (model.md "Gait and reference trajectories")."""
    ref = reference(p, 0.0)
    s = np.zeros(STATE_SIZE)
    q, dq = legs(s)
    q[:, 0:2] = ref.hip[0]
    dq[:, 0:2] = ref.hip_vel[0]
    q[:, 2:4] = ref.theta[0]
    dq[:, 2:4] = ref.theta_vel[0]
    return s


__all__ = ["W_SIZE", "accelerations", "advance", "advance_prepared", "euler_step", "initial_state",
           "leg_contact_solve", "observe", "observe_prepared", "prepare", "scratch", "solve",
           "state_ok"]
