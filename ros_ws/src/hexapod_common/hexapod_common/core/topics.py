"""The topic contract (graph.md "Topics") as data: names, the one topic table (type, QoS,
depth: :data:`TOPICS`, read by the nodes, the recorder and ``simulate --bag``), joint-name
lists, and the mapping between the engine's arrays and the (name, position, velocity,
effort) columns of each ``sensor_msgs/JointState`` topic. ROS-free: the nodes fill messages
from these arrays, the in-process recorder writes the same columns as CDR, and the analysis
reads them back.

Every JointState topic fills all three arrays (an empty trailing float64[] is padded by
rclpy's serializer in a way other readers reject, graph.md "Pitfalls").
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .layout import (C_DQREF, C_KD, C_KF, C_KP, C_QREF, C_TFF, COMMAND_SHAPE, O_FF, O_FP, O_FV,
                     O_HF, O_HP, O_HV, O_TH, O_THV, O_TQ)
from .params import N_LEGS

from .topic_names import *  # noqa: F403  (the names are part of this module's contract)
from .topic_names import (ACTIVE_CONTROLLER, CLOCK, FOOT_FORCES, HIP_STATES, INDICES,
                          JOINT_COMMANDS, JOINT_STATES, MARKERS, PARAMETERS, REFERENCE, STATUS)

#: Depth of the publishers' histories of the per-tick topics: how far (in ticks) a slow
#: reliable reader (the recorder) may lag before the writer drops samples for it.
HISTORY_DEPTH = 5000
#: Depth of the recorder's subscriptions (reader-side queue between two takes).
RECORD_DEPTH = 10000
#: Depth of the control loop's subscriptions (sim, controllers, trajectory generator,
#: markers): a process starved of CPU for up to this many ticks (0.2 s at 1 kHz), or a
#: topic flooded by a process outside the graph (whose messages are dropped, but fill the
#: queue first), still finds every message it needs. With 10, a controller taking over in
#: realtime mode on a loaded machine sometimes found the switch tick's state or inputs
#: rolled out of its queues and never answered it.
CONTROL_DEPTH = 200
#: Lockstep: ticks the recorder may be behind the sim before the sim holds the next tick
#: (well inside HISTORY_DEPTH: nothing is lost to the bag), and how often (ticks written)
#: the recorder says how far it is.
RECORDER_LAG = 1000
RECORDED_EVERY = 100

JOINT_STATE = "sensor_msgs/msg/JointState"
DIAGNOSTIC_ARRAY = "diagnostic_msgs/msg/DiagnosticArray"


@dataclass(frozen=True)
class TopicSpec:
    """One contract topic: message type (``pkg/msg/Name``), offered QoS (always reliable,
    keep-last; ``transient`` = transient-local durability) and publisher history depth.

    Reference and commands are transient-local so that a reader matched a little late (at
    start, or a controller or recorder started mid-run) still gets the recent samples.
    """

    msg_type: str
    transient: bool = False
    depth: int = HISTORY_DEPTH

    @property
    def preset(self) -> str:
        """The bag's QoS preset of this topic ('reliable' or 'transient_local')."""
        return "transient_local" if self.transient else "reliable"


#: The one topic table: every topic of the contract, as published, subscribed and recorded.
TOPICS: dict[str, TopicSpec] = {
    CLOCK: TopicSpec("rosgraph_msgs/msg/Clock"),
    JOINT_STATES: TopicSpec(JOINT_STATE),
    FOOT_FORCES: TopicSpec(JOINT_STATE),
    HIP_STATES: TopicSpec(JOINT_STATE),
    REFERENCE: TopicSpec(JOINT_STATE, transient=True),
    JOINT_COMMANDS: TopicSpec(JOINT_STATE, transient=True),
    ACTIVE_CONTROLLER: TopicSpec("std_msgs/msg/String", transient=True, depth=1),
    INDICES: TopicSpec(DIAGNOSTIC_ARRAY, depth=100),
    STATUS: TopicSpec(DIAGNOSTIC_ARRAY, depth=10),
    MARKERS: TopicSpec("visualization_msgs/msg/MarkerArray", depth=100),
    PARAMETERS: TopicSpec(DIAGNOSTIC_ARRAY, transient=True, depth=1000),
}
#: /hexapod/recorded: a header stamp, no status (signed like every topic of the graph).
RECORDED_SPEC = TopicSpec(DIAGNOSTIC_ARRAY, depth=10)

JOINT_NAMES = tuple(f"leg{i + 1}_{j}" for i in range(N_LEGS) for j in ("hip", "knee"))
FOOT_NAMES = tuple(f"leg{i + 1}_foot_{a}" for i in range(N_LEGS) for a in ("x", "y"))
HIP_NAMES = tuple(f"leg{i + 1}_hip_{a}" for i in range(N_LEGS) for a in ("x", "y"))
#: /hexapod/joint_commands with drive gains (docs/controllers.md): the 12 joints, then
#: ``<joint>/gains`` in the same order (position = kp, velocity = kd, effort = k_force).
DRIVE_GAIN_NAMES = tuple(f"{n}/gains" for n in JOINT_NAMES)
DRIVE_COMMAND_NAMES = JOINT_NAMES + DRIVE_GAIN_NAMES
#: /hexapod/reference: joint references, then desired hip and foot Cartesian coordinates.
REFERENCE_NAMES = JOINT_NAMES + HIP_NAMES + FOOT_NAMES

#: Observation rows carried by each state topic as (position, velocity, effort).
STATE_TOPICS = {
    JOINT_STATES: (JOINT_NAMES, (O_TH, O_THV, O_TQ)),
    FOOT_FORCES: (FOOT_NAMES, (O_FP, O_FV, O_FF)),
    HIP_STATES: (HIP_NAMES, (O_HP, O_HV, O_HF)),
}


class Columns(NamedTuple):
    """One JointState's payload: names and three equally long float arrays."""

    names: tuple[str, ...]
    position: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray


def state_columns(obs: np.ndarray, topic: str) -> Columns:
    """Columns of state ``topic`` from one observation (9, 6, 2); legs-major, 12 entries."""
    names, (rp, rv, re) = STATE_TOPICS[topic]
    return Columns(names, obs[rp].ravel(), obs[rv].ravel(), obs[re].ravel())


def obs_from_columns(cols: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]],
                     out: np.ndarray | None = None) -> np.ndarray:
    """Rebuild observation array(s) (..., 9, 6, 2) from the three state topics' arrays.

    ``cols[topic] = (position, velocity, effort)``, each (..., 12) in the contract's order.
    """
    lead = np.shape(next(iter(cols.values()))[0])[:-1]
    if out is None:
        out = np.empty(lead + (9, N_LEGS, 2))
    for topic, (_, rows) in STATE_TOPICS.items():
        for row, arr in zip(rows, cols[topic]):
            out[..., row, :, :] = np.asarray(arr).reshape(lead + (N_LEGS, 2))
    return out


def reference_columns(theta: np.ndarray, theta_vel: np.ndarray, hip: np.ndarray,
                      hip_vel: np.ndarray, foot: np.ndarray, foot_vel: np.ndarray) -> Columns:
    """Columns of /hexapod/reference at one instant from (6, 2) arrays; effort is zero."""
    pos = np.concatenate([theta.ravel(), hip.ravel(), foot.ravel()])
    vel = np.concatenate([theta_vel.ravel(), hip_vel.ravel(), foot_vel.ravel()])
    return Columns(REFERENCE_NAMES, pos, vel, np.zeros_like(pos))


def split_reference(position: np.ndarray, velocity: np.ndarray) -> dict[str, np.ndarray]:
    """Inverse of :func:`reference_columns` for arrays (..., 36): keys theta, theta_vel, hip,
    hip_vel, foot, foot_vel, each (..., 6, 2)."""
    lead = np.shape(position)[:-1]
    shape = lead + (N_LEGS, 2)
    out = {}
    for k, key in enumerate(("theta", "hip", "foot")):
        out[key] = np.asarray(position)[..., 12 * k:12 * (k + 1)].reshape(shape)
        out[key + "_vel"] = np.asarray(velocity)[..., 12 * k:12 * (k + 1)].reshape(shape)
    return out


def command_columns(demand: np.ndarray) -> Columns:
    """Columns of /hexapod/joint_commands: effort = demanded torque T_C (6, 2); position and
    velocity are zero (filled so every reader accepts the message)."""
    eff = np.asarray(demand, dtype=float).ravel()
    return Columns(JOINT_NAMES, np.zeros_like(eff), np.zeros_like(eff), eff)


def drive_command_columns(cmd: np.ndarray) -> Columns:
    """Columns of a 24-entry /hexapod/joint_commands from a drive command (6, 6, 2) (rows
    layout.COMMAND_FIELDS): the joints carry (q_ref, dq_ref, tau_ff), their ``/gains``
    entries (kp, kd, k_force)."""
    c = np.asarray(cmd, dtype=float).reshape(6, 2 * N_LEGS)
    return Columns(DRIVE_COMMAND_NAMES, np.concatenate([c[C_QREF], c[C_KP]]),
                   np.concatenate([c[C_DQREF], c[C_KD]]), np.concatenate([c[C_TFF], c[C_KF]]))


def drive_command(position: np.ndarray, velocity: np.ndarray, effort: np.ndarray
                  ) -> np.ndarray:
    """The drive command (6, 6, 2) of a 24-entry /hexapod/joint_commands (inverse of
    :func:`drive_command_columns`)."""
    n = 2 * N_LEGS
    cmd = np.empty(COMMAND_SHAPE)
    for row, arr, first in ((C_QREF, position, True), (C_KP, position, False),
                            (C_DQREF, velocity, True), (C_KD, velocity, False),
                            (C_TFF, effort, True), (C_KF, effort, False)):
        a = np.asarray(arr, dtype=float)
        cmd[row] = (a[:n] if first else a[n:2 * n]).reshape(N_LEGS, 2)
    return cmd


def stamp_ns(t: float) -> int:
    """Simulated time (s) -> integer nanoseconds, the stamp of every message of that tick."""
    return int(round(t * 1e9))


__all__ = [n for n in dir() if n.isupper()] + [
    "Columns", "TopicSpec", "command_columns", "drive_command", "drive_command_columns",
    "obs_from_columns", "reference_columns", "split_reference", "stamp_ns", "state_columns"]
