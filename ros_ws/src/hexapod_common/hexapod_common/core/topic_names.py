"""The graph's topic names (graph.md "Topics"), apart from the topic table (topics.py) so that
what needs only a name (the DDS profile, the command line) imports no numpy."""
from __future__ import annotations

JOINT_STATES = "/hexapod/joint_states"
FOOT_FORCES = "/hexapod/foot_forces"
HIP_STATES = "/hexapod/hip_states"
REFERENCE = "/hexapod/reference"
JOINT_COMMANDS = "/hexapod/joint_commands"
ACTIVE_CONTROLLER = "/hexapod/active_controller"
INDICES = "/hexapod/indices"
STATUS = "/hexapod/status"
CLOCK = "/clock"
MARKERS = "/hexapod/markers"
#: Parameter records (core/param_log.py): each node's start values and changes, transient-local.
PARAMETERS = "/hexapod/parameters"
#: The recorder's progress (lockstep pacing, hexapod_sim/core/recorder_pace.py): the stamp
#: of the newest joint state it wrote, every RECORDED_EVERY ticks. Not recorded itself.
RECORDED = "/hexapod/recorded"

#: The topics published at every control tick: the recorder cuts its chunks at the same
#: tick of all of them (so a killed recorder truncates them all at one tick).
TICK_TOPICS = (CLOCK, JOINT_STATES, FOOT_FORCES, HIP_STATES, REFERENCE, JOINT_COMMANDS)

__all__ = ["ACTIVE_CONTROLLER", "CLOCK", "FOOT_FORCES", "HIP_STATES", "INDICES", "JOINT_COMMANDS",
           "JOINT_STATES", "MARKERS", "PARAMETERS", "RECORDED", "REFERENCE", "STATUS",
           "TICK_TOPICS"]
