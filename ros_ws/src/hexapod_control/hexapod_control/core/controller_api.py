"""The controller contract: what a controller plug-in is, sees and answers.

A controller is a class registered by name (Python entry point group ``hexapod.controllers``,
``name = package.module:Class``; or a ``module:Class`` path for quick trials) with

- ``Params``: a frozen dataclass whose fields are made by :func:`param` (type, range,
  default, meaning: the same table-driven checks as every other parameter; the group is
  ``<name>.*`` in params files and ``--set``; a module:Class controller's name is its class
  attribute ``name``, default the class name in lower case);
- ``__init__(self, params, context)``: ``params`` a checked ``Params`` instance,
  ``context`` a :class:`Context` (control period, link lengths);
- ``reset()``: forget all state (called before tick 0 and when it takes charge);
- ``law(obs) -> DriveCommand``: called at every control tick with the tick's
  :class:`Observation`; the command is held by the drive until the next tick.

The drive (hexapod_sim.core.drive) evaluates per joint at every physics step
T = kp (q_ref + dq_ref (t - t_k) - q) + kd (dq_ref - dq) + tau_ff - k_force tau_F,
then the saturation of eq. 6. A torque-only command (:func:`torque_command`) is the
paper's setting: the drive applies tau_ff, held between ticks.
"""
from __future__ import annotations

from dataclasses import field
from typing import Any, ClassVar, NamedTuple, Protocol, runtime_checkable

import numpy as np

from hexapod_common.core.layout import O_FF, O_TH, O_THV, O_TQ
from hexapod_common.core.params import KIND_INFERRED, Spec

#: Shape of every per-joint array: (legs, joints).
JOINT_SHAPE = (6, 2)


class Context(NamedTuple):
    """What a controller may know of the run: control period (s) and link lengths (m)."""

    control_period: float
    leg_length_1: float
    leg_length_2: float


class Observation(NamedTuple):
    """The tick's sample, each array (6, 2) per leg and joint (hip, knee).

    t: tick time (s); theta, theta_vel: joint angles (rad) and rates (rad/s);
    foot_force: measured ground force on the foot (x, y) (N); theta_d, theta_vel_d: the
    references (rad, rad/s); torque: the torque acting now (N m); raw: the full sample
    (9, 6, 2) in hexapod_common.core.layout.OBS_FIELDS order.
    """

    t: float
    theta: np.ndarray
    theta_vel: np.ndarray
    foot_force: np.ndarray
    theta_d: np.ndarray
    theta_vel_d: np.ndarray
    torque: np.ndarray
    raw: np.ndarray


class DriveCommand(NamedTuple):
    """Per joint (6, 2) arrays: position and velocity setpoints (rad, rad/s), gains
    kp (N m/rad) and kd (N m s/rad), feed-forward torque (N m) and the gain on the
    foot-force torque k_force (1)."""

    q_ref: np.ndarray
    dq_ref: np.ndarray
    kp: np.ndarray
    kd: np.ndarray
    tau_ff: np.ndarray
    k_force: np.ndarray

    def stacked(self) -> np.ndarray:
        """The command as one (6, 6, 2) float array in field order (the drive's input);
        scalars and (2,) / (6, 1) arrays broadcast to (6, 2)."""
        try:  # fast path: six (6, 2) arrays
            fast = np.array(self, dtype=float)
            if fast.shape == (6,) + JOINT_SHAPE:
                return fast
        except ValueError:
            pass
        out = np.empty((6,) + JOINT_SHAPE)
        for k, a in enumerate(self):
            v = np.asarray(a, dtype=float)
            try:
                out[k] = np.broadcast_to(v, JOINT_SHAPE)
            except ValueError:
                raise ValueError(f"drive command field {self._fields[k]}: shape {v.shape} "
                                 f"does not broadcast to {JOINT_SHAPE} (legs, joints)") from None
        return out


def torque_command(torque: np.ndarray) -> DriveCommand:
    """A torque-only command: tau_ff = ``torque`` (6, 2) (N m), every gain zero."""
    z = np.zeros(JOINT_SHAPE)
    return DriveCommand(z, z, z, z, np.asarray(torque, dtype=float), z)


def call_law(ctrl: Any, t: float, raw: np.ndarray, theta_d: np.ndarray,
             theta_vel_d: np.ndarray) -> np.ndarray:
    """One tick of a controller instance: its ``law`` on the sample ``raw`` (9, 6, 2) at
    time ``t`` (s) with references theta_d, theta_vel_d (6, 2) (rad, rad/s), as the drive
    command (6, 6, 2) (rows layout.COMMAND_FIELDS). The law gets copies: what it keeps or
    changes never reaches the caller's arrays. The engine's per-tick loop and the graph's
    controller node both call this."""
    raw = raw.copy()
    o = Observation(t, raw[O_TH], raw[O_THV], raw[O_FF], theta_d.copy(), theta_vel_d.copy(),
                    raw[O_TQ], raw)
    cmd: np.ndarray = ctrl.law(o).stacked()
    return cmd


@runtime_checkable
class Controller(Protocol):
    """What a controller class provides (see the module docstring)."""

    Params: ClassVar[type]

    def reset(self) -> None:
        """Forget all state."""

    def law(self, obs: Observation) -> DriveCommand:
        """The drive command answering this tick."""


def param(description: str, lo: float | None = None, hi: float | None = None, *,
          default: Any, kind: type | None = None, lo_open: bool = False,
          hi_open: bool = False, choices: tuple[str, ...] = ()) -> Any:
    """A field of a controller's ``Params`` dataclass: range [lo, hi] (open ends by flag),
    allowed strings, default and a description with units.

    Its kind (``float``, ``int``, ``bool`` or ``str``) is ``kind`` if given, else the field's
    annotation (``warmup: int = param(...)`` takes whole numbers only: 2.5 is refused), else
    the default's type; the kind is settled when the controller is registered
    (params.register_controller_group), which also checks the default against it."""
    inferred = kind is None
    if kind is None:
        kind = type(default) if type(default) in (bool, int, str) else float
    spec = Spec(kind, description, lo, hi, lo_open, hi_open, choices, False, default)
    return field(default=default, metadata={"spec": spec, KIND_INFERRED: inferred})


__all__ = ["Context", "Controller", "DriveCommand", "JOINT_SHAPE", "Observation", "call_law",
           "param", "torque_command"]
