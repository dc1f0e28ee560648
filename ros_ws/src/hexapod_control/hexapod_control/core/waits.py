"""What a controller's states waited for: the counts behind missed realtime ticks.

A controller answers a state once the reference and the foot forces of its tick are there
(controller_node.py); a state whose inputs are late waits, and after ``CONTROL_DEPTH``
waiting states the oldest is given up unanswered. :class:`InputWaits` counts both, by
missing input, and is written in the controller's end summary in one format that the
graph launcher reads back (:func:`parse`) to say why ticks were missed.
"""
from __future__ import annotations

import re
from dataclasses import dataclass


@dataclass
class InputWaits:
    """Counts of one controller's waiting states (all since the node started)."""

    waited: int = 0  #: states whose reference or foot forces came after them
    reference: int = 0  #: of which the reference was missing (the generator behind)
    forces: int = 0  #: of which the foot forces were missing (the sim's, rare)
    given_up: int = 0  #: states given up unanswered: their inputs never came

    def count(self, reference_missing: bool, forces_missing: bool) -> bool:
        """One state waits, for the inputs said missing; a state that misses neither does
        not wait (it was answered; an older state is what waits): nothing counted, False."""
        if not (reference_missing or forces_missing):
            return False
        self.waited += 1
        self.reference += reference_missing
        self.forces += forces_missing
        return True

    def text(self) -> str:
        """The end summary's words (read back by :func:`parse`)."""
        return (f"{self.waited} waited for their reference or foot forces: {self.reference} "
                f"for the reference, {self.forces} for the foot forces; {self.given_up} "
                f"states given up unanswered, their inputs never came")

    def cause(self) -> str:
        """What the counts say, for a run's report (empty if nothing but tick 0 waited)."""
        if self.waited <= 1 and not self.given_up:
            return ""
        why = []
        if self.reference:
            why.append(f"{self.reference} for their reference (the trajectory generator "
                       f"behind: a machine too busy for this control rate?)")
        if self.forces:
            why.append(f"{self.forces} for their foot forces")
        return (f"{self.waited} states waited ({', '.join(why)}); {self.given_up} given up "
                f"unanswered")


_TEXT = re.compile(r"(\d+) waited for their reference or foot forces: (\d+) for the "
                   r"reference, (\d+) for the foot forces; (\d+) states given up")


def parse(log: str) -> InputWaits | None:
    """The counts of the last end summary in a controller's log (None if there is none)."""
    found = _TEXT.findall(log)
    if not found:
        return None
    waited, reference, forces, given_up = (int(x) for x in found[-1])
    return InputWaits(waited, reference, forces, given_up)


__all__ = ["InputWaits", "parse"]
