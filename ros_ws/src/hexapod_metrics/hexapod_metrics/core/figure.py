"""The stick figure of the hexapod at one sample: points shared by the GIF animation and the
Foxglove MarkerArray node, so both draw the same robot.

World frame of the model: x forward, y up (planar). Left legs (odd, 1-based) and right legs
(even) share the sagittal plane; drawings offset them sideways by :data:`SIDE_OFFSET`.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from hexapod_common.core.kinematics import knee_offset
from hexapod_common.core.layout import O_FF, O_FP, O_HP, O_TH

#: Lateral offset (m) of the left (+) and right (-) legs in 3-D drawings.
SIDE_OFFSET = 0.5
#: Metres of arrow per newton of ground reaction force.
FORCE_SCALE = 1.0 / 1000.0


class Figure(NamedTuple):
    """Points (6, 2) of hips, knees and feet (x, y), the contact mask and foot forces (N)."""

    hip: np.ndarray
    knee: np.ndarray
    foot: np.ndarray
    contact: np.ndarray
    force: np.ndarray


def stick_figure(obs: np.ndarray, l1: float) -> Figure:
    """Figure of one observation (9, 6, 2); ``l1`` is the thigh length (m)."""
    hip = obs[O_HP]
    dx, dy = knee_offset(obs[O_TH, :, 0], l1)
    knee = hip + np.stack([dx, dy], axis=-1)
    force = obs[O_FF]
    return Figure(hip, knee, obs[O_FP], force[:, 1] > 0.0, force)


def side(leg: int) -> float:
    """Lateral coordinate of leg ``leg`` (0-based): left legs +, right legs -."""
    return SIDE_OFFSET if leg % 2 == 0 else -SIDE_OFFSET


__all__ = ["FORCE_SCALE", "Figure", "SIDE_OFFSET", "side", "stick_figure"]
