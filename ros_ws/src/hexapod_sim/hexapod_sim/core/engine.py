"""The physics engine: state, one integration step, observation at a control tick.

[resolution, model.md "Time integration"] Semi-implicit Euler at dt (default 1e-4 s):
dq += dt ddq, then q += dt dq; the contact state is updated every step. The joint torques
are held constant between control ticks (zero-order hold) by the caller.

Observation convention (used by the engine, the sim node and the analysis alike): the sample
at tick k holds the state at t_k and the torque *acting at that instant*, i.e. the held torque
T_{k-1} applied over (t_{k-1}, t_k]; the hip force f_i is evaluated at the same state with the
same torque. Index sums pair them over the window's samples 1..N (see indices.py).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .body import body_forces
from .contact import ground_force
from .dynamics import leg_accel
from .errors import DivergenceError
from .gait import reference
from .kinematics import foot_offset
from .layout import (C0, O_FF, O_FP, O_FV, O_HF, O_HP, O_HV, O_TH, O_THV, O_TQ,
                     OBS_SHAPE, P_BBX, P_BBY, P_BGX, P_BGY, P_DT, P_G, P_HIPX, P_KBX, P_KBY,
                     P_KGX, P_KGY, P_L1, P_L2, P_MF, P_MH, P_MK, P_MU, Q0, STATE_SIZE, V0, X0,
                     model_vector)
from .params import N_LEGS, HexapodParams

#: A state is diverged when non-finite or beyond these magnitudes (m or rad, m/s or rad/s).
MAX_COORD = 1e4
MAX_RATE = 1e4


@njit(cache=True)
def accelerations(s, torque, P, fh, ff, qdd):  # type: ignore[no-untyped-def]
    """Forces and accelerations at state ``s`` under joint torques ``torque`` (6, 2) (N m).

    Updates the contact state stored in ``s`` (idempotent for one state) and writes
    F_RH into fh (6, 2), F_RF into ff (6, 2) and ddq into qdd (6, 4).
    """
    q = s[Q0:Q0 + 24].reshape(N_LEGS, 4)
    dq = s[V0:V0 + 24].reshape(N_LEGS, 4)
    l1, l2 = P[P_L1], P[P_L2]
    body_forces(q, dq, P[P_HIPX:P_HIPX + N_LEGS], P[P_KBX], P[P_KBY], P[P_BBX], P[P_BBY], fh)
    for i in range(N_LEGS):
        th1, th2, w1, w2 = q[i, 2], q[i, 3], dq[i, 2], dq[i, 3]
        dx, dy = foot_offset(th1, th2, l1, l2)
        # foot velocity = hip velocity + J_F,theta dtheta, with J_F,theta = -J (kinematics.py)
        w12 = w1 + w2
        c1, s1, c12, s12 = np.cos(th1), np.sin(th1), np.cos(th1 + th2), np.sin(th1 + th2)
        vx = dq[i, 0] + l1 * c1 * w1 + l2 * c12 * w12
        vy = dq[i, 1] + l1 * s1 * w1 + l2 * s12 * w12
        fx, fy, c, xt = ground_force(q[i, 0] + dx, q[i, 1] + dy, vx, vy, s[C0 + i], s[X0 + i],
                                     P[P_KGX], P[P_KGY], P[P_BGX], P[P_BGY], P[P_MU])
        s[C0 + i] = c
        s[X0 + i] = xt
        ff[i, 0] = fx
        ff[i, 1] = fy
        a0, a1, a2, a3 = leg_accel(th1, th2, w1, w2, l1, l2, P[P_MH], P[P_MK], P[P_MF], P[P_G],
                                   torque[i, 0], torque[i, 1], fh[i, 0], fh[i, 1], fx, fy)
        qdd[i, 0] = a0
        qdd[i, 1] = a1
        qdd[i, 2] = a2
        qdd[i, 3] = a3


@njit(cache=True)
def advance(s, torque, P, n_steps):  # type: ignore[no-untyped-def]
    """Integrate ``n_steps`` physics steps of P[P_DT] under the held ``torque`` (6, 2), in place.

    Returns False (and stops) as soon as the state diverges.
    """
    fh = np.empty((N_LEGS, 2))
    ff = np.empty((N_LEGS, 2))
    qdd = np.empty((N_LEGS, 4))
    dt = P[P_DT]
    for _ in range(n_steps):
        accelerations(s, torque, P, fh, ff, qdd)
        for i in range(N_LEGS):
            for j in range(4):
                v = s[V0 + 4 * i + j] + dt * qdd[i, j]
                s[V0 + 4 * i + j] = v
                s[Q0 + 4 * i + j] += dt * v
    return state_ok(s)


@njit(cache=True)
def state_ok(s):  # type: ignore[no-untyped-def]
    """True while the state is finite and within :data:`MAX_COORD` / :data:`MAX_RATE`."""
    for k in range(24):
        a = s[Q0 + k]
        v = s[V0 + k]
        if not (abs(a) < MAX_COORD and abs(v) < MAX_RATE):  # also false for NaN
            return False
    return True


@njit(cache=True)
def observe(s, torque_held, P, obs):  # type: ignore[no-untyped-def]
    """Fill ``obs`` (9, 6, 2) with the sample of the current tick (see module docstring)."""
    fh = np.empty((N_LEGS, 2))
    ff = np.empty((N_LEGS, 2))
    qdd = np.empty((N_LEGS, 4))
    accelerations(s, torque_held, P, fh, ff, qdd)
    l1, l2, mh, grav = P[P_L1], P[P_L2], P[P_MH], P[P_G]
    for i in range(N_LEGS):
        xh, yh, th1, th2 = s[Q0 + 4 * i], s[Q0 + 4 * i + 1], s[Q0 + 4 * i + 2], s[Q0 + 4 * i + 3]
        vxh, vyh = s[V0 + 4 * i], s[V0 + 4 * i + 1]
        w1, w2 = s[V0 + 4 * i + 2], s[V0 + 4 * i + 3]
        dx, dy = foot_offset(th1, th2, l1, l2)
        w12 = w1 + w2
        obs[O_TH, i, 0], obs[O_TH, i, 1] = th1, th2
        obs[O_THV, i, 0], obs[O_THV, i, 1] = w1, w2
        obs[O_TQ, i, 0], obs[O_TQ, i, 1] = torque_held[i, 0], torque_held[i, 1]
        obs[O_FP, i, 0], obs[O_FP, i, 1] = xh + dx, yh + dy
        obs[O_FV, i, 0] = vxh + l1 * np.cos(th1) * w1 + l2 * np.cos(th1 + th2) * w12
        obs[O_FV, i, 1] = vyh + l1 * np.sin(th1) * w1 + l2 * np.sin(th1 + th2) * w12
        obs[O_FF, i, 0], obs[O_FF, i, 1] = ff[i, 0], ff[i, 1]
        obs[O_HP, i, 0], obs[O_HP, i, 1] = xh, yh
        obs[O_HV, i, 0], obs[O_HV, i, 1] = vxh, vyh
        # f_i = m_H (ddp_H - [0, -g]) - F_RH,i: the force leg i exerts on its body segment.
        obs[O_HF, i, 0] = mh * qdd[i, 0] - fh[i, 0]
        obs[O_HF, i, 1] = mh * (qdd[i, 1] + grav) - fh[i, 1]


def initial_state(p: HexapodParams) -> np.ndarray:
    """Hips at p_Hd(0) moving at [V_F, 0], joints at theta_d(0) moving at dtheta_d(0),
    no stored contacts (model.md "Gait and reference trajectories")."""
    ref = reference(p, 0.0)
    s = np.zeros(STATE_SIZE)
    q = s[Q0:Q0 + 24].reshape(N_LEGS, 4)
    dq = s[V0:V0 + 24].reshape(N_LEGS, 4)
    q[:, 0:2] = ref.hip[0]
    dq[:, 0:2] = ref.hip_vel[0]
    q[:, 2:4] = ref.theta[0]
    dq[:, 2:4] = ref.theta_vel[0]
    return s


class Physics:
    """The stepping object the sim node and scripts use: owns the state and the model vector.

    ``torque`` is the held actuator torque T_m (6, 2) (N m); :meth:`advance_tick` integrates
    one control period with it; :meth:`observe` returns the tick's sample (9, 6, 2).
    """

    def __init__(self, p: HexapodParams) -> None:
        self.params = p
        self.P = model_vector(p)
        self.state = initial_state(p)
        self.torque = np.zeros((N_LEGS, 2))
        self.substeps = p.substeps
        self.tick = 0

    @property
    def time(self) -> float:
        """Simulated time of the current tick (s)."""
        return self.tick * self.params.sim.control_period

    def set_params(self, p: HexapodParams) -> None:
        """Take new physical parameters (ground, actuator, ...) from the next step on."""
        self.params = p
        self.P = model_vector(p)

    def observe(self) -> np.ndarray:
        """Sample of the current tick: state and the torque acting now."""
        obs = np.empty(OBS_SHAPE)
        observe(self.state, self.torque, self.P, obs)
        return obs

    def advance_tick(self, torque: np.ndarray) -> None:
        """Hold ``torque`` (already saturated) for one control period and integrate it."""
        self.torque = np.ascontiguousarray(torque, dtype=float).reshape(N_LEGS, 2)
        if not advance(self.state, self.torque, self.P, self.substeps):
            raise DivergenceError(f"state diverged between t = {self.time:.4f} s and the next "
                                  f"tick (non-finite or beyond {MAX_COORD:g})")
        self.tick += 1


__all__ = ["Physics", "accelerations", "advance", "initial_state", "observe", "state_ok"]
