"""Wave gait, cycloid foot trajectory, hip line and joint references (paper eqs. 1-4).

Everything is a pure function of time and parameters; arrays are (N, 6) per coordinate,
legs numbered 0..5 here (leg i of the paper is index i-1). Positions in m (world frame),
velocities in m/s, angles in rad.

[resolution, model.md] The paper's eq. (1a) advances the foot by V_F t_T per transfer,
which contradicts eq. (2); here the foot advances one stride L_S = V_F T.

This module lives with the model (not in hexapod_control as first sketched): parameter
validation needs it to reject unreachable gaits, the engine starts every run at the gait's
pose at t = 0, and the indices measure errors against it. It imports nothing of
``params``: its functions take any :class:`GaitModel` (``HexapodParams`` is one), so
``params`` can use it without an import cycle.
"""
from __future__ import annotations

from functools import lru_cache
from typing import Any, NamedTuple, Protocol

import numpy as np
from .jit import njit

from .errors import UnreachableTargetError
from .kinematics import N_LEGS, ik_with_rates


class GaitModel(Protocol):
    """What the gait reads of the parameters (``HexapodParams`` is one): ``gait.velocity``
    (m/s), ``gait.step_length``, ``gait.foot_clearance``, ``gait.body_height`` (m),
    ``gait.duty_factor``; ``robot.leg_length_1``, ``robot.leg_length_2``,
    ``robot.stroke_pitch``, ``robot.foot_offset`` (m); ``cycle_time`` (s)."""

    @property
    def gait(self) -> Any: ...
    @property
    def robot(self) -> Any: ...
    @property
    def cycle_time(self) -> float: ...


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


def hip_offsets(p: GaitModel) -> np.ndarray:
    """Nominal hip x offsets x0_i = -pair * S_P (m), legs 0..5."""
    return -(np.arange(N_LEGS) // 2) * float(p.robot.stroke_pitch)


@njit(cache=True, error_model="numpy")
def _reference_kernel(t, phi, x0, period, t_t, t_s, velocity, step_length, clearance,  # type: ignore[no-untyped-def]
                      body_height, foot_offset, l1, l2, joints, out, support):
    """Eqs. (1)-(4) at every time of ``t`` (N,), legs 0..5, in one compiled pass.

    out (N, 6, 6, 2) receives hip, hip_vel, foot, foot_vel, theta, theta_vel (the order of
    :class:`Reference`); support (N, 6) the stance flags. With ``joints`` False the joint
    references are left untouched (Cartesian only). Returns -1, or the first flat sample
    index whose hip-foot distance leaves the annulus |L1-L2| <= r <= L1+L2.
    """
    two_pi = 2.0 * np.pi
    r_max, r_min = l1 + l2, abs(l1 - l2)
    for n in range(t.shape[0]):
        for i in range(6):
            ti = t[n] - phi[i] * period
            k = np.floor(ti / period)
            tau = ti - k * period
            stance = tau >= t_t
            hx = velocity * t[n] + x0[i]
            if stance:
                fx = (velocity * (phi[i] * period + k * period + t_t) + x0[i]
                      + velocity * t_s / 2.0 + foot_offset)
                fy, vx, vy = 0.0, 0.0, 0.0
            else:
                s = tau / t_t
                a = two_pi * s
                land_prev = (velocity * (phi[i] * period + (k - 1.0) * period + t_t) + x0[i]
                             + velocity * t_s / 2.0 + foot_offset)
                fx = land_prev + step_length * (s - np.sin(a) / two_pi)
                fy = 0.5 * clearance * (1.0 - np.cos(a))
                vx = step_length * (1.0 - np.cos(a)) / t_t
                vy = 0.5 * clearance * np.sin(a) * two_pi / t_t
            support[n, i] = stance
            out[n, 0, i, 0], out[n, 0, i, 1] = hx, body_height
            out[n, 1, i, 0], out[n, 1, i, 1] = velocity, 0.0
            out[n, 2, i, 0], out[n, 2, i, 1] = fx, fy
            out[n, 3, i, 0], out[n, 3, i, 1] = vx, vy
            if joints:
                px, py = hx - fx, body_height - fy
                r2 = px * px + py * py
                r = np.sqrt(r2)
                if not (r_min <= r <= r_max):
                    return n * 6 + i
                th1, th2, w1, w2 = ik_with_rates(px, py, r2, velocity - vx, -vy, l1, l2)
                out[n, 4, i, 0], out[n, 4, i, 1] = th1, th2
                out[n, 5, i, 0], out[n, 5, i, 1] = w1, w2
    return -1


def _reference_arrays(p: GaitModel, t: np.ndarray, joints: bool, compiled: bool = True
                      ) -> tuple[np.ndarray, np.ndarray, int]:
    g = p.gait
    kernel: Any = _reference_kernel if compiled else _reference_kernel.py_func
    period = g.step_length / g.velocity
    out = np.empty((t.shape[0], 6, N_LEGS, 2))
    support = np.empty((t.shape[0], N_LEGS), dtype=np.bool_)
    bad = kernel(t, phases(g.duty_factor), hip_offsets(p).astype(float), period,
                 (1.0 - g.duty_factor) * period, g.duty_factor * period, g.velocity,
                 g.step_length, g.foot_clearance, g.body_height, p.robot.foot_offset,
                 p.robot.leg_length_1, p.robot.leg_length_2, joints, out, support)
    return out, support, bad


def cartesian_reference(p: GaitModel, t: np.ndarray) -> tuple[np.ndarray, ...]:
    """Hip and foot desired positions and velocities at times t (paper eqs. 1-3).

    Returns (hip, hip_vel, foot, foot_vel, support) with shapes (N, 6, 2) and (N, 6).
    """
    t = np.ascontiguousarray(np.asarray(t, dtype=float).reshape(-1))
    out, support, _ = _reference_arrays(p, t, False)
    return out[:, 0], out[:, 1], out[:, 2], out[:, 3], support


def reference(p: GaitModel, t: np.ndarray | float) -> Reference:
    """Full reference at times t: Cartesian (eqs. 1-3) and joint (eqs. 4a-4c).

    One compiled pass over all samples (the in-process loop asks for a whole run or block
    at once; the trajectory node for a block of ticks). Raises
    :class:`~.errors.UnreachableTargetError` if the gait leaves the leg's reach.
    """
    t = np.ascontiguousarray(np.atleast_1d(np.asarray(t, dtype=float)).reshape(-1))
    out, support, bad = _reference_arrays(p, t, True)
    if bad >= 0:
        n, i = divmod(bad, N_LEGS)
        rel = out[n, 0, i] - out[n, 2, i]
        raise UnreachableTargetError(
            f"IK target |p| = {float(np.hypot(*rel)):.6g} m outside the leg's reach "
            f"[{abs(p.robot.leg_length_1 - p.robot.leg_length_2):.6g}, "
            f"{p.robot.leg_length_1 + p.robot.leg_length_2:.6g}] m")
    return Reference(t, out[:, 0], out[:, 1], out[:, 2], out[:, 3], out[:, 4], out[:, 5],
                     support)


def reach_bounds(p: GaitModel, samples: int = 2001) -> tuple[float, float]:
    """Smallest and largest hip-foot distance |p_Hd - p_Fd| over one gait cycle (m).

    Parameter validation runs this wherever parameters are read, also in processes that
    never run compiled code (``hexapod analyze`` reading a bag's parameters): so it runs the
    same kernel interpreted (``py_func``, ~30-50 ms for 12,006 samples here) instead of
    loading the compiled one (0.3-0.8 s in a fresh process, measured). The result depends on
    the gait and robot groups only and is kept per distinct pair: a sweep validates hundreds
    of parameter sets that differ in ground or gains (half of a 128-point sweep's time went
    here before, docs/benchmarks.md).
    """
    return _reach_bounds(p.gait, p.robot, float(p.cycle_time), samples)


class _GaitOnly(NamedTuple):
    gait: Any
    robot: Any
    cycle_time: float


@lru_cache(maxsize=1024)
def _reach_bounds(gait: Any, robot: Any, cycle_time: float, samples: int
                  ) -> tuple[float, float]:
    p = _GaitOnly(gait, robot, cycle_time)
    t = np.linspace(0.0, p.cycle_time, samples)
    out, _, _ = _reference_arrays(p, t, False, compiled=False)
    hip, foot = out[:, 0], out[:, 2]
    r = np.hypot(*np.moveaxis(hip - foot, -1, 0))
    return float(r.min()), float(r.max())


__all__ = ["GaitModel", "Reference", "cartesian_reference", "hip_offsets", "phases", "reach_bounds",
           "reference"]
