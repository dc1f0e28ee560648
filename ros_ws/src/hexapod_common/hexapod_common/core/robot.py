"""The robot's fixed shape (model.md): six legs, three a side, each a planar two-link chain
(hip and knee joints). A module of its own so that the parameters (params.py) and the
compiled kinematics (kinematics.py) both read it without importing each other, and the
command line starts without numba."""
from __future__ import annotations

#: Legs of the robot.
N_LEGS = 6

__all__ = ["N_LEGS"]
