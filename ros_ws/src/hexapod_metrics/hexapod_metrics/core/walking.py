"""A walk or not: whether a gait cycle (any evaluation window) was walked (model docs,
"A walk or not"; ours: the paper scores only walks and says nothing of falls).

A window is a walk when, over its samples,

* every hip stays within ``HIP_BAND`` x H_B of the body height H_B (normal walks on 10 % to
  1000 % ground, T_max 170 to inf, stay within 0.035 m = 0.02 H_B; a collapse under T_max 100
  takes the hips through the ground: their y goes negative),
* no foot goes deeper than ``MAX_DEPTH`` below the ground surface y = 0 (the deepest stance
  on 10 % ground is 6 mm; a foot 50 mm down is sinking, not standing), and
* the body moved forward by ``MIN_PROGRESS`` to ``MAX_PROGRESS`` x V_F (t_b - t_a) (normal
  walks make 0.98 to 1.08 of it; a fallen body makes little or negative progress, a thrown
  one too much). The tuner's older rule (50-150 % of the distance) is this one.

The indices of a window that is not a walk mean nothing (an "energy per metre" of a body
thrown backwards is negative): such a window is ``fallen``, its indices are not reported
as numbers, and the engine, sweeps, Monte Carlo and the tuner reject the run as they
reject a diverged one.
"""
from __future__ import annotations

import math

from hexapod_common.core.params import HexapodParams

from .indices import WindowSums

#: A hip may move this fraction of H_B away from H_B (0.18 m on the paper's robot).
HIP_BAND = 0.1
#: A foot may sink this far below the ground surface (m).
MAX_DEPTH = 0.05
#: The body walks at least this fraction of the commanded V_F (t_b - t_a).
MIN_PROGRESS = 0.5
#: ... and at most this fraction.
MAX_PROGRESS = 1.5
#: The label of a window that was not a walk.
FALLEN = "fallen"


def not_walking(sums: WindowSums, p: HexapodParams) -> str | None:
    """Why the window of ``sums`` was not a walk (one line), or None if it was one."""
    h_b = p.gait.body_height
    lo, hi = sums.hip_y
    if math.isnan(lo):
        return None  # not recorded (an older accumulator): nothing to tell
    if not (abs(lo - h_b) <= HIP_BAND * h_b and abs(hi - h_b) <= HIP_BAND * h_b):
        return (f"{FALLEN}: hip height {lo:.3g}..{hi:.3g} m, outside "
                f"H_B = {h_b:g} m +- {HIP_BAND * h_b:.3g} m")
    if sums.foot_y_min < -MAX_DEPTH:
        return (f"{FALLEN}: a foot {-sums.foot_y_min:.3g} m below the ground "
                f"(at most {MAX_DEPTH:g} m)")
    commanded = p.gait.velocity * sums.span
    if not MIN_PROGRESS * commanded <= sums.distance <= MAX_PROGRESS * commanded:
        return (f"{FALLEN}: walked {sums.distance:.3g} m in {sums.span:.3g} s, outside "
                f"{MIN_PROGRESS:g}..{MAX_PROGRESS:g} x V_F t = {commanded:.3g} m")
    return None


__all__ = ["FALLEN", "HIP_BAND", "MAX_DEPTH", "MAX_PROGRESS", "MIN_PROGRESS", "not_walking"]
