"""Wave gait, cycloid foot trajectory, hip line and joint references (paper eqs. 1-4).

Everything is a pure function of time and parameters; arrays are (N, 6) per coordinate,
legs numbered 0..5 here (leg i of the paper is index i-1). Positions in m (world frame),
velocities in m/s, angles in rad.

[resolution, model.md] The paper's eq. (1a) advances the foot by V_F t_T per transfer,
which contradicts eq. (2); here the foot advances one stride L_S = V_F T.

This module lives with the model (not in hexapod_control as first sketched) because
parameter validation needs it to reject unreachable gaits.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .kinematics import inverse_kinematics, joint_rates
from .params import N_LEGS, HexapodParams


class Reference(NamedTuple):
    """Desired trajectories at times ``t`` (N,); every other field is (N, 6) or (N, 6, 2)."""

    t: np.ndarray
    hip: np.ndarray        # p_Hd (N, 6, 2)
    hip_vel: np.ndarray    # dp_Hd/dt (N, 6, 2)
    foot: np.ndarray       # p_Fd (N, 6, 2)
    foot_vel: np.ndarray   # dp_Fd/dt (N, 6, 2)
    theta: np.ndarray      # theta_d (N, 6, 2): [hip joint, knee joint]
    theta_vel: np.ndarray  # dtheta_d/dt (N, 6, 2)
    support: np.ndarray    # (N, 6) bool, True in the stance phase


def phases(beta: float) -> np.ndarray:
    """Wave-gait phases phi_i (fractions of T), legs 0..5: phi_{2m+1} = frac(m beta),
    phi_{2m+2} = frac(phi_{2m+1} + 1/2)."""
    phi = np.empty(N_LEGS)
    for m in range(N_LEGS // 2):
        phi[2 * m] = (m * beta) % 1.0
        phi[2 * m + 1] = (phi[2 * m] + 0.5) % 1.0
    return phi


def hip_offsets(p: HexapodParams) -> np.ndarray:
    """Nominal hip x offsets x0_i = -pair * S_P (m), legs 0..5."""
    return -(np.arange(N_LEGS) // 2) * p.robot.stroke_pitch


def cartesian_reference(p: HexapodParams, t: np.ndarray) -> tuple[np.ndarray, ...]:
    """Hip and foot desired positions and velocities at times t (paper eqs. 1-3).

    Returns (hip, hip_vel, foot, foot_vel, support) with shapes (N, 6, 2) and (N, 6).
    """
    g = p.gait
    t = np.asarray(t, dtype=float).reshape(-1, 1)
    period = g.step_length / g.velocity
    t_t = (1.0 - g.duty_factor) * period
    t_s = g.duty_factor * period
    phi = phases(g.duty_factor)[None, :]
    x0 = hip_offsets(p)[None, :]

    ti = t - phi * period
    k = np.floor(ti / period)
    tau = ti - k * period
    support = tau >= t_t

    def x_land(cycle: np.ndarray) -> np.ndarray:
        return (g.velocity * (phi * period + cycle * period + t_t) + x0
                + g.velocity * t_s / 2.0 + p.robot.foot_offset)

    s = np.where(support, 0.0, tau / t_t)
    two_pi_s = 2.0 * np.pi * s
    x_tr = x_land(k - 1) + g.step_length * (s - np.sin(two_pi_s) / (2.0 * np.pi))
    y_tr = 0.5 * g.foot_clearance * (1.0 - np.cos(two_pi_s))
    vx_tr = g.step_length * (1.0 - np.cos(two_pi_s)) / t_t
    vy_tr = 0.5 * g.foot_clearance * np.sin(two_pi_s) * 2.0 * np.pi / t_t

    n = t.shape[0]
    foot = np.empty((n, N_LEGS, 2))
    foot_vel = np.empty((n, N_LEGS, 2))
    foot[..., 0] = np.where(support, x_land(k), x_tr)
    foot[..., 1] = np.where(support, 0.0, y_tr)
    foot_vel[..., 0] = np.where(support, 0.0, vx_tr)
    foot_vel[..., 1] = np.where(support, 0.0, vy_tr)

    hip = np.empty((n, N_LEGS, 2))
    hip[..., 0] = g.velocity * t + x0
    hip[..., 1] = g.body_height
    hip_vel = np.zeros((n, N_LEGS, 2))
    hip_vel[..., 0] = g.velocity
    return hip, hip_vel, foot, foot_vel, support


def reference(p: HexapodParams, t: np.ndarray | float) -> Reference:
    """Full reference at times t: Cartesian (eqs. 1-3) and joint (eqs. 4a-4c).

    Raises :class:`~.errors.UnreachableTargetError` if the gait leaves the leg's reach.
    """
    t = np.atleast_1d(np.asarray(t, dtype=float))
    hip, hip_vel, foot, foot_vel, support = cartesian_reference(p, t)
    l1, l2 = p.robot.leg_length_1, p.robot.leg_length_2
    rel = hip - foot
    rel_vel = hip_vel - foot_vel
    th1, th2 = inverse_kinematics(rel[..., 0], rel[..., 1], l1, l2)
    w1, w2 = joint_rates(th1, th2, rel_vel[..., 0], rel_vel[..., 1], l1, l2)
    theta = np.stack([th1, th2], axis=-1)
    theta_vel = np.stack([w1, w2], axis=-1)
    return Reference(t, hip, hip_vel, foot, foot_vel, theta, theta_vel, support)


def reach_bounds(p: HexapodParams, samples: int = 2001) -> tuple[float, float]:
    """Smallest and largest hip-foot distance |p_Hd - p_Fd| over one gait cycle (m)."""
    t = np.linspace(0.0, p.cycle_time, samples)
    hip, _, foot, _, _ = cartesian_reference(p, t)
    r = np.hypot(*np.moveaxis(hip - foot, -1, 0))
    return float(r.min()), float(r.max())


__all__ = ["Reference", "cartesian_reference", "hip_offsets", "phases", "reach_bounds",
           "reference"]
