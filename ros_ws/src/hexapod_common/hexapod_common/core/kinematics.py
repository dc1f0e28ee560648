"""Planar two-link leg kinematics (model.md "Per-leg coordinates and kinematics").

Frame: world x forward, y up. theta1 is the thigh angle from the downward vertical,
positive swinging the thigh forward; theta2 is the knee angle relative to the thigh.

    knee  p_K = p_H + L1 [sin th1, -cos th1]
    foot  p_F = p_K + L2 [sin(th1+th2), -cos(th1+th2)]
    Psi(theta) = p_H - p_F          (hip relative to foot, paper eq. 4b)
    J = dPsi/dtheta                  (2x2, paper eq. 4c)

The compiled functions accept scalars or numpy arrays (numba specialises per type), so the
engine's inner loop, the trajectory generator and the controllers share one implementation.
"""
from __future__ import annotations

import numpy as np
from .jit import njit

from .errors import UnreachableTargetError
from .robot import N_LEGS


@njit(cache=True)
def knee_offset(th1, l1):  # type: ignore[no-untyped-def]
    """Knee minus hip, (dx, dy) in m."""
    return l1 * np.sin(th1), -l1 * np.cos(th1)


@njit(cache=True)
def foot_offset(th1, th2, l1, l2):  # type: ignore[no-untyped-def]
    """Foot minus hip, (dx, dy) in m; equals -Psi(theta)."""
    a = th1 + th2
    return foot_offset_cs(np.cos(th1), np.sin(th1), np.cos(a), np.sin(a), l1, l2)


@njit(cache=True, forceinline=True)
def foot_offset_cs(c1, s1, c12, s12, l1, l2):  # type: ignore[no-untyped-def]
    """Foot minus hip (m) from cos/sin of theta1 and of theta1 + theta2."""
    return l1 * s1 + l2 * s12, -l1 * c1 - l2 * c12


@njit(cache=True, forceinline=True)
def foot_velocity_cs(c1, s1, c12, s12, w1, w2, l1, l2):  # type: ignore[no-untyped-def]
    """Foot velocity relative to the hip (m/s): J_F,theta dtheta = -J dtheta."""
    w12 = w1 + w2
    return l1 * c1 * w1 + l2 * c12 * w12, l1 * s1 * w1 + l2 * s12 * w12


@njit(cache=True)
def psi(th1, th2, l1, l2):  # type: ignore[no-untyped-def]
    """Psi(theta) = p_H - p_F, hip relative to foot (m), paper eq. (4b)."""
    dx, dy = foot_offset(th1, th2, l1, l2)
    return -dx, -dy


@njit(cache=True, forceinline=True)
def psi_jacobian(th1, th2, l1, l2):  # type: ignore[no-untyped-def]
    """J = dPsi/dtheta as (J11, J12, J21, J22), paper eq. (4c)."""
    a = th1 + th2
    c1, s1, ca, sa = np.cos(th1), np.sin(th1), np.cos(a), np.sin(a)
    return -l1 * c1 - l2 * ca, -l2 * ca, -l1 * s1 - l2 * sa, -l2 * sa


@njit(cache=True)
def joint_rates(th1, th2, vx, vy, l1, l2):  # type: ignore[no-untyped-def]
    """theta_dot = J^-1 v for a hip-relative-to-foot velocity v = d/dt Psi (rad/s)."""
    j11, j12, j21, j22 = psi_jacobian(th1, th2, l1, l2)
    det = j11 * j22 - j12 * j21
    return (j22 * vx - j12 * vy) / det, (-j21 * vx + j11 * vy) / det


@njit(cache=True, forceinline=True)
def foot_force_torque(th1, th2, fx, fy, l1, l2):  # type: ignore[no-untyped-def]
    """Joint torques (N m) produced by a force F (N) at the foot: theta rows of J_F^T F.

    J_F's theta columns are dp_F/dtheta = -J, so this is -J^T F.
    """
    j11, j12, j21, j22 = psi_jacobian(th1, th2, l1, l2)
    return -(j11 * fx + j21 * fy), -(j12 * fx + j22 * fy)


@njit(cache=True, error_model="numpy")
def _ik_parts(px, py, r2, l1, l2):  # type: ignore[no-untyped-def]
    """theta1, theta2 of a reachable target and cos, sin of theta2 (forward knee)."""
    # Foot relative to hip, measured in a frame whose first axis points down.
    c2 = min(1.0, max(-1.0, (r2 - l1 * l1 - l2 * l2) / (2.0 * l1 * l2)))
    s2 = -np.sqrt(1.0 - c2 * c2)  # sin(theta2), theta2 = -arccos(c2) <= 0
    th1 = np.arctan2(-px, py) - np.arctan2(l2 * s2, l1 + l2 * c2)
    return th1, -np.arccos(c2), c2, s2


@njit(cache=True, error_model="numpy")
def ik_scalar(px, py, r2, l1, l2):  # type: ignore[no-untyped-def]
    """theta = Psi^-1(p) of one reachable target p = p_H - p_F with r2 = |p|^2 (forward knee).

    The caller checks the reach; this is the formula shared by :func:`inverse_kinematics`
    and the compiled reference of the gait.
    """
    th1, th2, _, _ = _ik_parts(px, py, r2, l1, l2)
    return th1, th2


@njit(cache=True, error_model="numpy")
def ik_with_rates(px, py, r2, vx, vy, l1, l2):  # type: ignore[no-untyped-def]
    """:func:`ik_scalar` and :func:`joint_rates` of the same target in one go (paper eqs.
    4b-4c), J's trigonometry replaced by algebra: with a = L1 + L2 cos th2, b = L2 sin th2,
    cos th1 = (p_y a - p_x b) / r^2, sin th1 = (-p_x a - p_y b) / r^2, and J's first column is
    (-p_y, p_x). Returns th1, th2 (rad), their rates (rad/s) for v = d/dt Psi (m/s)."""
    th1, th2, c2, s2 = _ik_parts(px, py, r2, l1, l2)
    a, b = l1 + l2 * c2, l2 * s2
    c1 = (py * a - px * b) / r2
    s1 = (-px * a - py * b) / r2
    c12 = c1 * c2 - s1 * s2
    s12 = s1 * c2 + c1 * s2
    j11, j12, j21, j22 = -py, -l2 * c12, px, -l2 * s12
    det = j11 * j22 - j12 * j21
    return th1, th2, (j22 * vx - j12 * vy) / det, (-j21 * vx + j11 * vy) / det


def inverse_kinematics(px: np.ndarray | float, py: np.ndarray | float, l1: float,
                       l2: float) -> tuple[np.ndarray, np.ndarray]:
    """theta = Psi^-1(p) for p = p_H - p_F, forward knee (theta2 < 0), paper eq. (4b).

    Raises :class:`UnreachableTargetError` if any target lies outside the annulus
    |L1 - L2| <= |p| <= L1 + L2; never clips.
    """
    px = np.asarray(px, dtype=float)
    py = np.asarray(py, dtype=float)
    r2 = px * px + py * py
    r = np.sqrt(r2)
    bad = (r > l1 + l2) | (r < abs(l1 - l2)) | ~np.isfinite(r)
    if np.any(bad):
        k = int(np.flatnonzero(np.ravel(bad))[0])
        raise UnreachableTargetError(
            f"IK target |p| = {np.ravel(r)[k]:.6g} m outside the leg's reach "
            f"[{abs(l1 - l2):.6g}, {l1 + l2:.6g}] m")
    th1 = np.empty(np.shape(r2))
    th2 = np.empty(np.shape(r2))
    for k, (x, y, rr) in enumerate(zip(px.flat, py.flat, r2.flat)):
        th1.flat[k], th2.flat[k] = ik_scalar(float(x), float(y), float(rr), l1, l2)
    return (th1[()], th2[()]) if th1.ndim == 0 else (th1, th2)


__all__ = ["N_LEGS", "foot_force_torque", "foot_offset", "foot_offset_cs", "foot_velocity_cs",
           "ik_scalar", "ik_with_rates", "inverse_kinematics", "joint_rates",
           "knee_offset", "psi", "psi_jacobian"]
