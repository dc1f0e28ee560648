"""The same planar leg model built in MuJoCo: the yardstick of benchmark S3 (quality.md).

One leg (model.md "Per-leg coordinates", "Masses", "Dynamics") becomes three bodies:

- ``hip``: two slide joints along world x and y, so that ``qpos[0:2] = (x_H, y_H)``; its
  inertial is the hip point mass m_H = M_b / 6 at the body origin.
- ``thigh``: a hinge about +z at the hip; its inertial is the knee point mass M_1 at the
  distal end, local (0, -L1, 0).
- ``shank``: a body at the knee, a hinge about +z; its inertial is the foot point mass M_2
  at local (0, -L2, 0).

Angle conventions: a rotation by ``a`` about +z maps (0, -L) to (L sin a, -L cos a), so the
hinge angles are exactly model.md's theta1 (from the downward vertical, positive swinging
the thigh forward, +x) and theta2 (relative to the thigh): MuJoCo's ``qpos`` equals our
``q = [x_H, y_H, theta1, theta2]`` with no offset or sign change, and ``qvel`` equals ``dq``.

Rotational inertias are 1e-12 kg m^2 (MuJoCo needs positive ones; ours are zero), which
perturbs H by ~1e-12 relative. Gravity is 9.81 m/s^2 along -y, contacts are disabled, the
time step is ``p.sim.dt``, and the integrator is MuJoCo's ``Euler`` with implicit damping
disabled (``eulerdamp``), i.e. the same semi-implicit Euler as ours: qvel += dt qacc, then
qpos += dt qvel. Two motors (gear 1, unlimited) apply the joint torques: ``ctrl = T_m``.

The six-leg model (:func:`build_hexapod_model`) has six such legs side by side and the body
compliance of model.md as fixed tendons: for a link (a, b) a tendon of length x_b - x_a
with spring length x0_b - x0_a (both negated when that is negative: MuJoCo reads a spring
length of -1 as "the length at qpos0"), stiffness K_bx and damping B_bx (likewise along y
with spring length 0) produces exactly F_x = K_bx (x_b - x_a - (x0_b - x0_a)) + B_bx
(dx_b - dx_a) on a and the opposite on b. There is no ground contact in it (MuJoCo's
contact model differs from the paper's spring-dashpot with a stored touchdown point), so it
matches our engine only while the ground forces are zero; it serves the step-rate
comparison and an integration check with the ground switched off.

``mujoco`` is imported lazily: this module can be imported without it.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from hexapod_common.core.layout import GRAVITY
from hexapod_common.core.params import N_LEGS, HexapodParams

if TYPE_CHECKING:  # pragma: no cover
    import mujoco

#: Rotational inertia given to every body (kg m^2): MuJoCo rejects zero, ours is zero.
TINY_INERTIA = 1e-12

# The links of model.md "Body compliance" (0-based legs), same order as core/body.py.
_BODY_LINKS = ((0, 1), (2, 3), (4, 5), (0, 2), (2, 4), (1, 3), (3, 5))


def _mujoco() -> Any:
    try:
        import mujoco
    except ImportError as err:  # pragma: no cover - depends on the environment
        raise ImportError("the MuJoCo comparison needs the 'mujoco' package "
                          "(pip install mujoco)") from err
    return mujoco


def _leg_xml(prefix: str, l1: float, l2: float, mh: float, mk: float, mf: float) -> str:
    i = TINY_INERTIA
    return f"""
    <body name="{prefix}hip" pos="0 0 0">
      <joint name="{prefix}x_H" type="slide" axis="1 0 0"/>
      <joint name="{prefix}y_H" type="slide" axis="0 1 0"/>
      <inertial pos="0 0 0" mass="{mh!r}" diaginertia="{i!r} {i!r} {i!r}"/>
      <body name="{prefix}thigh" pos="0 0 0">
        <joint name="{prefix}theta1" type="hinge" axis="0 0 1"/>
        <inertial pos="0 {-l1!r} 0" mass="{mk!r}" diaginertia="{i!r} {i!r} {i!r}"/>
        <body name="{prefix}shank" pos="0 {-l1!r} 0">
          <joint name="{prefix}theta2" type="hinge" axis="0 0 1"/>
          <inertial pos="0 {-l2!r} 0" mass="{mf!r}" diaginertia="{i!r} {i!r} {i!r}"/>
        </body>
      </body>
    </body>"""


def _motors_xml(prefix: str) -> str:
    return (f'    <motor name="{prefix}T_m1" joint="{prefix}theta1" gear="1"/>\n'
            f'    <motor name="{prefix}T_m2" joint="{prefix}theta2" gear="1"/>\n')


def _option_xml(dt: float, grav: float) -> str:
    return f"""
  <compiler angle="radian" inertiafromgeom="false" autolimits="true"/>
  <option timestep="{dt!r}" gravity="0 {-grav!r} 0" integrator="Euler">
    <flag contact="disable" eulerdamp="disable"/>
  </option>"""


def _leg_values(p: HexapodParams) -> tuple[float, float, float, float, float]:
    r = p.robot
    return r.leg_length_1, r.leg_length_2, r.body_mass / N_LEGS, r.mass_1, r.mass_2


def leg_xml(p: HexapodParams) -> str:
    """MJCF text of the one-leg model of ``p`` (see the module docstring)."""
    return (f'<mujoco model="hexapod_leg">{_option_xml(p.sim.dt, GRAVITY)}\n'
            f'  <worldbody>{_leg_xml("", *_leg_values(p))}\n  </worldbody>\n'
            f'  <actuator>\n{_motors_xml("")}  </actuator>\n</mujoco>\n')


def hexapod_xml(p: HexapodParams, body_springs: bool = True) -> str:
    """MJCF text of six independent legs, joined by the body spring-dashpots as fixed tendons
    when ``body_springs`` (the default); no ground contact."""
    legs = "".join(_leg_xml(f"leg{i + 1}_", *_leg_values(p)) for i in range(N_LEGS))
    motors = "".join(_motors_xml(f"leg{i + 1}_") for i in range(N_LEGS))
    tendons = ""
    if body_springs:
        b = p.body
        x0 = -(np.arange(N_LEGS) // 2) * p.robot.stroke_pitch
        rows = []
        for a, c in _BODY_LINKS:
            for axis, k, d, rest in (("x", b.k_x, b.b_x, float(x0[c] - x0[a])),
                                     ("y", b.k_y, b.b_y, 0.0)):
                # Length x_c - x_a with rest x0_c - x0_a, or its negative: MuJoCo reads a
                # spring length of -1 as "the length at qpos0", so keep the rest length >= 0.
                sign = 1.0 if rest >= 0.0 else -1.0
                rows.append(
                    f'    <fixed name="link{a + 1}{c + 1}_{axis}" stiffness="{k!r}" '
                    f'damping="{d!r}" springlength="{sign * rest!r}">\n'
                    f'      <joint joint="leg{c + 1}_{axis}_H" coef="{sign!r}"/>\n'
                    f'      <joint joint="leg{a + 1}_{axis}_H" coef="{-sign!r}"/>\n'
                    f'    </fixed>\n')
        tendons = "  <tendon>\n" + "".join(rows) + "  </tendon>\n"
    return (f'<mujoco model="hexapod_planar">{_option_xml(p.sim.dt, GRAVITY)}\n'
            f'  <worldbody>{legs}\n  </worldbody>\n{tendons}'
            f'  <actuator>\n{motors}  </actuator>\n</mujoco>\n')


def build_leg_model(p: HexapodParams) -> "mujoco.MjModel":
    """One leg of ``p`` as a MuJoCo model: qpos = [x_H, y_H, theta1, theta2], ctrl = T_m."""
    return _mujoco().MjModel.from_xml_string(leg_xml(p))


def build_hexapod_model(p: HexapodParams, body_springs: bool = True) -> "mujoco.MjModel":
    """Six legs (qpos = our q, leg-major, 24 values; ctrl = T_m (6, 2) flattened) with the
    body compliance as fixed tendons; no ground contact."""
    return _mujoco().MjModel.from_xml_string(hexapod_xml(p, body_springs))


def set_leg_state(model: "mujoco.MjModel", data: "mujoco.MjData", q: np.ndarray,
                  dq: np.ndarray) -> None:
    """Put our generalized coordinates and rates into ``data`` (any number of legs)."""
    data.qpos[:] = np.asarray(q, dtype=float).ravel()
    data.qvel[:] = np.asarray(dq, dtype=float).ravel()


def mass_matrix_and_bias(model: "mujoco.MjModel", data: "mujoco.MjData", q: np.ndarray,
                         dq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """MuJoCo's dense mass matrix H (nv x nv) and bias c + g (``qfrc_bias``, nv) at (q, dq)."""
    mujoco = _mujoco()
    set_leg_state(model, data, q, dq)
    mujoco.mj_forward(model, data)
    H = np.zeros((model.nv, model.nv))
    try:
        mujoco.mj_fullM(model, data, H)  # mujoco 4.0
    except TypeError:  # mujoco 2.x / 3.x: mj_fullM(model, dst, qM)
        mujoco.mj_fullM(model, H, data.qM)
    return H, data.qfrc_bias.copy()


def leg_accel(model: "mujoco.MjModel", data: "mujoco.MjData", q: np.ndarray, dq: np.ndarray,
              torque: np.ndarray | None = None, hip_force: np.ndarray | None = None,
              foot_force: np.ndarray | None = None) -> np.ndarray:
    """MuJoCo's qacc of the one-leg model under joint torques T_m (2,) via the motors, a
    force on the hip point and a force on the foot point (N, world frame) via
    ``xfrc_applied`` (applied at each body's centre of mass: the hip and the foot)."""
    mujoco = _mujoco()
    set_leg_state(model, data, q, dq)
    data.ctrl[:] = 0.0 if torque is None else np.asarray(torque, dtype=float)
    data.xfrc_applied[:] = 0.0
    hip = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "hip")
    foot = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "shank")
    if hip_force is not None:
        data.xfrc_applied[hip, 0:2] = hip_force
    if foot_force is not None:
        data.xfrc_applied[foot, 0:2] = foot_force
    mujoco.mj_forward(model, data)
    return data.qacc.copy()


__all__ = ["TINY_INERTIA", "build_hexapod_model", "build_leg_model", "hexapod_xml",
           "leg_accel", "leg_xml", "mass_matrix_and_bias", "set_leg_state"]
