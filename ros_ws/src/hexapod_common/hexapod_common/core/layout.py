"""Flat array layouts shared by the compiled engine, the nodes and the batch runner.

State vector ``s`` (float64, length :data:`STATE_SIZE`):
    s[Q0:Q0+24]   q  = per leg [x_H, y_H, theta1, theta2]  (m, m, rad, rad), leg-major
    s[V0:V0+24]   dq = their time derivatives
    s[C0:C0+6]    1.0 while foot i is in contact, else 0.0
    s[X0:X0+6]    stored touchdown point x_0 of foot i (m), valid while in contact
    (optional tail beyond STATE_SIZE: uneven ground, see hexapod_sim/core/uneven_ground.py)

Model vector ``P`` (float64, length :data:`MODEL_SIZE`): the physical parameters in SI units,
effective ground values (base x scale), the integrator flag and the nominal hip offsets.

Observation ``obs`` (float64, shape (9, 6, 2)) at one control tick, rows :data:`OBS_FIELDS`.

Constants only (no numba): the command line and the topic table import them and start
fast; the compiled views into a state vector are the engine's (``engine.legs``).
"""
from __future__ import annotations

import numpy as np

from .params import N_LEGS, HexapodParams

Q0, V0, C0, X0 = 0, 24, 48, 54
STATE_SIZE = 60

(P_L1, P_L2, P_MH, P_MK, P_MF, P_G, P_KBX, P_KBY, P_BBX, P_BBY, P_KGX, P_KGY, P_BGX, P_BGY,
 P_MU, P_TMAX, P_DT, P_IMPL, P_HIPX) = range(19)
MODEL_SIZE = P_HIPX + N_LEGS
GRAVITY = 9.81

OBS_FIELDS = ("theta", "theta_vel", "torque", "foot_pos", "foot_vel", "foot_force",
              "hip_pos", "hip_vel", "hip_force")
(O_TH, O_THV, O_TQ, O_FP, O_FV, O_FF, O_HP, O_HV, O_HF) = range(9)
OBS_SHAPE = (len(OBS_FIELDS), N_LEGS, 2)

#: A drive command (model.md "Drive interface"), float64 (6, 6, 2): rows COMMAND_FIELDS per
#: leg and joint (rad, rad/s, N m/rad, N m s/rad, N m, 1).
COMMAND_FIELDS = ("q_ref", "dq_ref", "kp", "kd", "tau_ff", "k_force")
C_QREF, C_DQREF, C_KP, C_KD, C_TFF, C_KF = range(6)
COMMAND_SHAPE = (len(COMMAND_FIELDS), N_LEGS, 2)


def model_vector(p: HexapodParams) -> np.ndarray:
    """Pack the physical parameters of ``p`` into the engine's model vector ``P``."""
    P = np.zeros(MODEL_SIZE)
    r, b, g = p.robot, p.body, p.ground
    P[P_L1], P[P_L2] = r.leg_length_1, r.leg_length_2
    P[P_MH], P[P_MK], P[P_MF] = r.body_mass / N_LEGS, r.mass_1, r.mass_2
    P[P_G] = GRAVITY
    P[P_KBX], P[P_KBY], P[P_BBX], P[P_BBY] = b.k_x, b.k_y, b.b_x, b.b_y
    P[P_KGX], P[P_KGY] = g.k_x * g.scale, g.k_y * g.scale
    P[P_BGX], P[P_BGY] = g.b_x * g.scale, g.b_y * g.scale
    P[P_MU] = g.friction_mu
    P[P_TMAX] = p.actuator.t_max
    P[P_DT] = p.sim.dt
    P[P_IMPL] = 1.0 if p.sim.integrator == "implicit_ground_damping" else 0.0
    P[P_HIPX:P_HIPX + N_LEGS] = -(np.arange(N_LEGS) // 2) * r.stroke_pitch
    return P


__all__ = [name for name in dir() if name.isupper() or name == "model_vector"]
