"""Who commanded each tick's torque: the one rule that writes and reads it (ROS-free).

The sim's ``/hexapod/joint_states`` of tick k carries it in ``header.frame_id``:

* ``<controller>``: the controller in charge at tick k (the one that answers this state),
  and the torque in this message's effort (T_{k-1}, engine.py's sample convention) was
  commanded by the controller in charge at tick k-1;
* ``<controller>/held``: T_{k-1} was not commanded: the last torque was held (no command in
  time);
* ``<controller>/fallback``: T_{k-1} was the joint-damping fallback.

Clean runs carry the bare name, so their bytes are those of a run without labels. The torque
of tick j (acting over [t_j, t_{j+1}]) is thus labelled by the controller named in sample j
and the source named in sample j+1. A gait cycle over ticks k_a..k_b is named by
:func:`cycle_label`: the controller (``a->b`` across a switch) if every torque of
k_a..k_b-1 was commanded, else ``fallback`` / ``held`` (none was) or
``mixed(<controller>+N uncommanded)``.
"""
from __future__ import annotations

from collections.abc import Sequence

#: Sources of a torque: commanded by the controller in charge, held, damping fallback.
COMMANDED = ""
HELD = "held"
FALLBACK = "fallback"
SOURCES = (COMMANDED, HELD, FALLBACK)
SEPARATOR = "/"
#: The controller of a state whose frame_id is empty (bags without labels).
UNKNOWN = "unknown"


def state_frame(controller: str, source: str = COMMANDED) -> str:
    """frame_id of a joint_states sample: the controller in charge and the source of the
    torque it carries."""
    if source not in SOURCES:
        raise ValueError(f"torque source {source!r} is not one of {SOURCES}")
    return controller if source == COMMANDED else f"{controller}{SEPARATOR}{source}"


def parse_state_frame(frame_id: str) -> tuple[str, str]:
    """(controller in charge, torque source) of a joint_states frame_id; an unknown suffix
    is kept as the source, an empty frame_id names :data:`UNKNOWN`."""
    controller, _, source = frame_id.partition(SEPARATOR)
    return controller or UNKNOWN, source


def in_charge(frame_id: str) -> str:
    """The controller in charge named by a joint_states frame_id."""
    return parse_state_frame(frame_id)[0]


def cycle_label(controllers: Sequence[str], sources: Sequence[str]) -> tuple[str, str, int]:
    """(label, controllers in charge, uncommanded ticks) of the torques of one cycle.

    ``controllers[i]`` and ``sources[i]``: who was in charge of torque tick i and where the
    torque came from (see the module doc)."""
    names: list[str] = []
    for c in controllers:
        if not names or names[-1] != c:
            names.append(c)
    who = "->".join(names)
    uncommanded = sum(1 for s in sources if s != COMMANDED)
    if uncommanded == 0:
        return who, who, 0
    if uncommanded >= len(sources):
        return (FALLBACK if FALLBACK in sources else HELD), who, uncommanded
    return f"mixed({who}+{uncommanded} uncommanded)", who, uncommanded


__all__ = ["COMMANDED", "FALLBACK", "HELD", "SEPARATOR", "SOURCES", "UNKNOWN", "cycle_label",
           "in_charge", "parse_state_frame", "state_frame"]
