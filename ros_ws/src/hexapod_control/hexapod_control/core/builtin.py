"""PD-P and PD-P&F as controller plug-ins (registered as ``pd_p`` and ``pd_pf``).

Both keep their compiled fast path: while a run's command is torque-only (PD-P, and PD-P&F
with ``force_loop: topic``) the closed loop runs the compiled law (``compiled_code``) and
never calls :meth:`law`; :meth:`law` computes the same numbers for the generic per-tick loop.
PD-P&F with ``force_loop: drive`` puts its inner force loop into the drive
(model.md "Drive interface"): kp = K_f Kp, kd = K_f Kd, k_force = K_f, q_ref and dq_ref the
references, tau_ff = 0, evaluated at every physics step.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from hexapod_common.core.params import GainParams

from .controller_api import Context, DriveCommand, Observation, param, torque_command
from .controllers import PD_P, PD_PF, control_law, gain_vector, pd_pf_drive_command

#: Force-loop placements of PD-P&F.
FORCE_LOOPS = ("topic", "drive")


@dataclass(frozen=True)
class PdPfParams(GainParams):
    """PD-P&F's gains and where its inner force loop runs."""

    force_loop: str = param("inner force loop: 'topic' (the controller's tick, the paper's "
                            "sampled law) or 'drive' (every physics step in the drive)",
                            default="topic", kind=str, choices=FORCE_LOOPS)


class _Compiled:
    """A built-in law: the compiled control_law of hexapod_control.core.controllers."""

    Params: ClassVar[type] = GainParams
    compiled_code: ClassVar[int] = PD_P

    def __init__(self, params: GainParams, context: Context) -> None:
        self.params = params
        self.context = context
        self.gains = gain_vector(params)
        self._out = np.empty((6, 2))

    def reset(self) -> None:
        """Nothing to forget: the law is static."""

    @property
    def torque_only(self) -> bool:
        """True when every command is torque-only (the compiled fast path applies)."""
        return True

    def law(self, obs: Observation) -> DriveCommand:
        """T_C of the compiled law as a torque-only command."""
        control_law(self.compiled_code, self.gains, obs.raw, obs.theta_d, obs.theta_vel_d,
                    self.context.leg_length_1, self.context.leg_length_2, self._out)
        return torque_command(self._out.copy())


class PdP(_Compiled):
    """PD-P: T_C = K_f (Kp e + Kd de) (paper eq. 7, no force feedback)."""

    Params = GainParams
    compiled_code = PD_P


class PdPf(_Compiled):
    """PD-P&F: T_C = K_f (Kp e + Kd de - tau_F) (model.md "Controllers")."""

    Params = PdPfParams
    compiled_code = PD_PF

    @property
    def torque_only(self) -> bool:
        """Only with the force loop over the topic (at the controller's tick)."""
        return str(getattr(self.params, "force_loop", "topic")) == "topic"

    def law(self, obs: Observation) -> DriveCommand:
        """Topic: the compiled law's T_C. Drive: the PD and force gains go to the drive."""
        if self.torque_only:
            return super().law(obs)
        cmd = np.empty((6,) + self._out.shape)
        pd_pf_drive_command(self.gains, obs.theta_d, obs.theta_vel_d, cmd)
        return DriveCommand(*cmd)


__all__ = ["FORCE_LOOPS", "PdP", "PdPf", "PdPfParams"]
