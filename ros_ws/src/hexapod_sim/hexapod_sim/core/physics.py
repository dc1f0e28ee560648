"""The stepping object of the sim node: the state, the model vector and the held command.

:class:`Physics` integrates one control period at a time, either holding a saturated torque
(engine.advance_prepared, eq. 6) or with the drive evaluating a drive command at every
physics step (drive.drive_advance, model.md "Drive interface"). The in-process closed loop
(hexapod_control.core.closed_loop) runs the same compiled functions without this object.
"""
from __future__ import annotations

import numpy as np

from hexapod_common.core.errors import DivergenceError
from hexapod_common.core.layout import OBS_SHAPE, model_vector
from hexapod_common.core.params import N_LEGS, HexapodParams

from .drive import drive_advance
from .uneven_ground import GroundDraws, GroundRecord, touchdowns
from .engine import (MAX_COORD, advance_prepared, initial_state, observe_prepared, prepare,
                     scratch, solve)


class Physics:
    """The stepping object the sim node and scripts use: owns the state and the model vector.

    ``torque`` is the held actuator torque T_m (6, 2) (N m); :meth:`advance_tick` integrates
    one control period with it; :meth:`observe` returns the tick's sample (9, 6, 2). The
    first physics step of :meth:`advance_tick` reuses the state part that :meth:`observe`
    computed at the same state (same numbers, bit for bit, as recomputing it).
    """

    def __init__(self, p: HexapodParams, ground: GroundDraws | None = None) -> None:
        """``ground``: uneven ground (uneven_ground.py), its draws in the state's tail."""
        self.params = p
        self.P = model_vector(p)
        self.state = initial_state(p) if ground is None else ground.attach(initial_state(p))
        self.ground = ground
        self.torque = np.zeros((N_LEGS, 2))
        self.substeps = p.substeps
        self.tick = 0
        self._scratch = scratch()
        self._prepared = False  # the scratch holds the state part of self.state, self.P

    @property
    def time(self) -> float:
        """Simulated time of the current tick (s)."""
        return self.tick * self.params.sim.control_period

    def set_params(self, p: HexapodParams) -> None:
        """Take new physical parameters (ground, actuator, ...) from the next step on."""
        self.params = p
        self.P = model_vector(p)
        self._prepared = False

    def observe(self) -> np.ndarray:
        """Sample of the current tick: state and the torque acting now."""
        obs = np.empty(OBS_SHAPE)
        observe_prepared(self.state, self.torque, self.P, obs, *self._scratch)
        self._prepared = True
        return obs

    def advance_tick(self, torque: np.ndarray) -> None:
        """Hold ``torque`` (already saturated) for one control period and integrate it."""
        self.torque = np.ascontiguousarray(torque, dtype=float).reshape(N_LEGS, 2)
        fh, work, ff, qdd = self._scratch
        if not self._prepared:
            prepare(self.state, self.P, fh, work)
        self._prepared = False
        if not advance_prepared(self.state, self.torque, self.P, self.substeps, fh, work, ff,
                                qdd):
            raise DivergenceError(f"state diverged between t = {self.time:.4f} s and the next "
                                  f"tick (non-finite or beyond {MAX_COORD:g})")
        self.tick += 1

    def ground_record(self) -> GroundRecord | None:
        """The uneven ground used so far (None on uniform ground)."""
        if self.ground is None:
            return None
        return GroundRecord(self.ground, tuple(int(c) for c in touchdowns(self.state)))

    def advance_drive(self, cmd: np.ndarray) -> None:
        """Integrate one control period with the drive holding ``cmd`` (6, 6, 2) (rows
        layout.COMMAND_FIELDS; drive.py evaluates it at every physics step, t_k = this
        tick); ``torque`` ends as the last step's T_m."""
        fh, work, ff, qdd = self._scratch
        torque = self.torque.copy()
        if not self._prepared:  # the state part and the foot force under the acting torque
            prepare(self.state, self.P, fh, work)
            solve(self.state, torque, self.P, fh, work, ff, qdd)
        self._prepared = False
        demand0 = np.empty((N_LEGS, 2))
        if not drive_advance(self.state, np.ascontiguousarray(cmd, dtype=float), self.P,
                             self.substeps, fh, work, ff, qdd, demand0, torque):
            raise DivergenceError(f"state diverged between t = {self.time:.4f} s and the next "
                                  f"tick (non-finite or beyond {MAX_COORD:g})")
        self.torque = torque
        self.tick += 1



__all__ = ["Physics"]
