"""What a bag of this project holds, and writing an in-process run in exactly that format.

:data:`TOPICS` is the one table of recorded topics (type and offered QoS) shared by the
metrics node and ``hexapod simulate --bag``; the analysis reads either kind of bag.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from hexapod_control.core.closed_loop import RunResult
from hexapod_sim.core import topics as T
from hexapod_sim.core.layout import O_HP
from hexapod_sim.core.param_log import RECORD_NAME, ParamRecord
from hexapod_sim.core.params import SPECS, HexapodParams, from_flat

from hexapod_sim.core import cdr
from hexapod_sim.core.cdr import DiagnosticStatus

from ..bag import BagWriter
from .indices import REPORTED_NAMES, Indices, indices_from_obs

JOINT_STATE = "sensor_msgs/msg/JointState"
PARAMS_KEY = "hexapod_params"
#: metadata.yaml custom_data key mirroring the MCAP's parameter records (JSON list of maps).
RECORDS_KEY = "hexapod_parameter_records"
#: The node whose start values are the run's model parameters in metadata.yaml's mirror.
SIM_NODE = "hexapod_sim"
#: The writer of in-process bags, as named in their parameter records.
SIMULATE_NODE = "hexapod simulate"
#: topic -> (message type, offered QoS preset of bag.QOS_PRESETS)
TOPICS: dict[str, tuple[str, str]] = {
    T.CLOCK: ("rosgraph_msgs/msg/Clock", "reliable"),
    T.JOINT_STATES: (JOINT_STATE, "reliable"),
    T.FOOT_FORCES: (JOINT_STATE, "reliable"),
    T.HIP_STATES: (JOINT_STATE, "reliable"),
    T.REFERENCE: (JOINT_STATE, "reliable"),
    T.JOINT_COMMANDS: (JOINT_STATE, "reliable"),
    T.ACTIVE_CONTROLLER: ("std_msgs/msg/String", "transient_local"),
    T.INDICES: ("diagnostic_msgs/msg/DiagnosticArray", "reliable"),
    T.STATUS: ("diagnostic_msgs/msg/DiagnosticArray", "reliable"),
    T.MARKERS: ("visualization_msgs/msg/MarkerArray", "reliable"),
    T.PARAMETERS: ("diagnostic_msgs/msg/DiagnosticArray", "transient_local"),
}
#: The topics published at every control tick: the recorder cuts its chunks at the same
#: tick of all of them (so a killed recorder truncates them all at one tick).
TICK_TOPICS = (T.CLOCK, T.JOINT_STATES, T.FOOT_FORCES, T.HIP_STATES, T.REFERENCE,
               T.JOINT_COMMANDS)


def params_from_custom_data(custom: dict[str, str] | None) -> HexapodParams | None:
    """The parameters in a bag's custom_data (older bags, without MCAP records), or None."""
    if not custom or PARAMS_KEY not in custom:
        return None
    return from_flat(json.loads(custom[PARAMS_KEY]))


def param_status(rec: ParamRecord) -> DiagnosticStatus:
    """The /hexapod/parameters status of one record: name, kind, payload and checksum."""
    return DiagnosticStatus(name=f"{RECORD_NAME}/{rec.node}", message=rec.kind,
                            hardware_id="hexapod", level=0,
                            values=tuple(sorted(rec.to_map().items())))


class ParamRecorder:
    """Puts parameter records into a bag: the /hexapod/parameters message (log time = the
    tick it took effect), an MCAP Metadata record (checksummed) and metadata.yaml's mirror.

    A record already stored (same checksum) is ignored, so a redelivered one is harmless.
    ``custom_data[PARAMS_KEY]`` (the run's model parameters, read by older tools) mirrors
    the start values of ``params_node``.
    """

    def __init__(self, bag: BagWriter, params_node: str = SIM_NODE) -> None:
        """``params_node``: the node whose start values metadata.yaml's PARAMS_KEY mirrors."""
        self.bag = bag
        self.params_node = params_node
        self.records: list[ParamRecord] = []
        self._seen: set[str] = set()

    def add(self, rec: ParamRecord, data: bytes | None = None) -> bool:
        """Store ``rec`` (``data``: its message as received, else encoded here); False if
        it was there already."""
        if rec.sha256 in self._seen:
            return False
        self._seen.add(rec.sha256)
        self.records.append(rec)
        if data is None:
            data = cdr.encode_diagnostic_array(rec.stamp_ns, [param_status(rec)])
        self.bag.write(T.PARAMETERS, rec.stamp_ns, data)
        self.bag.add_metadata(RECORD_NAME, rec.to_map())
        self.bag.set_custom_data(RECORDS_KEY, json.dumps([r.to_map() for r in self.records]))
        if rec.kind == "start" and rec.node == self.params_node:
            flat = {k: v for k, v in rec.values.items() if k in SPECS}
            self.bag.set_custom_data(PARAMS_KEY, json.dumps(flat))
        return True


def indices_status(idx: Indices, controller: str, cycle: int, t_a: float,
                   t_b: float, lag_growth: float = float("nan")) -> DiagnosticStatus:
    """One /hexapod/indices status: the seven indices of gait cycle ``cycle``, L, the hip lag
    and its growth since the previous cycle (m per cycle)."""
    values = tuple((n, repr(float(getattr(idx, n)))) for n in REPORTED_NAMES)
    values += (("lag_growth", repr(float(lag_growth))), ("controller", controller),
               ("cycle", str(cycle)), ("t_a", repr(t_a)), ("t_b", repr(t_b)))
    return DiagnosticStatus(name=f"hexapod/indices/{controller}", message=f"cycle {cycle}",
                            hardware_id="hexapod", level=0, values=values)


def status_indices(status: DiagnosticStatus) -> tuple[Indices, dict[str, str]]:
    """Inverse of :func:`indices_status`: the indices and the other key/values."""
    kv = dict(status.values)
    idx = Indices(**{n: float(kv.pop(n, "nan")) for n in REPORTED_NAMES})
    return idx, kv


def write_run_bag(run: RunResult, path: str | Path) -> Path:
    """Write an in-process run as the graph would record it (every tick of every topic).

    Log time = stamp = simulated time. The command of tick k answers the state of tick k;
    the per-cycle indices are published at the end of each full gait cycle.
    """
    path = Path(path)
    p = run.params
    ref = run.reference
    n_ticks = run.command.shape[0]
    ticks_per_cycle = int(round(p.cycle_time / p.sim.control_period))
    with BagWriter(path, custom_data={"source": SIMULATE_NODE}) as bag:
        for name, (msgtype, qos) in TOPICS.items():
            if name not in (T.STATUS, T.MARKERS):  # published by nodes only
                bag.add_topic(name, msgtype, qos)
        records = ParamRecorder(bag, params_node=SIMULATE_NODE)
        records.add(ParamRecord(SIMULATE_NODE, "start", 0, 0, p.to_flat()))
        changes: dict[int, dict[str, object]] = {}
        for k, values in run.param_changes:
            changes.setdefault(k, {}).update(values)
        switch_ticks = dict(run.switches)
        last = n_ticks if run.diverged_at is None else int(round(
            run.diverged_at / p.sim.control_period))
        for k in range(last + 1):
            stamp = T.stamp_ns(run.t[k])
            obs = run.obs[k]
            who = run.controller_at(k)
            if k in changes:
                records.add(ParamRecord(SIMULATE_NODE, "change", k, stamp, changes[k]))
            if k in switch_ticks:
                bag.write_string(T.ACTIVE_CONTROLLER, stamp, who)
            bag.write_clock(T.CLOCK, stamp)
            for topic in T.STATE_TOPICS:
                c = T.state_columns(obs, topic)
                bag.write_joint_state(topic, stamp, c.names, c.position, c.velocity, c.effort,
                                      frame_id=who if topic == T.JOINT_STATES else "")
            c = T.reference_columns(ref.theta[k], ref.theta_vel[k], ref.hip[k], ref.hip_vel[k],
                                    ref.foot[k], ref.foot_vel[k])
            bag.write_joint_state(T.REFERENCE, stamp, c.names, c.position, c.velocity, c.effort)
            if k < last:
                c = T.command_columns(run.command[k])
                bag.write_joint_state(T.JOINT_COMMANDS, stamp, c.names, c.position, c.velocity,
                                      c.effort, frame_id=who)
            if k > 0 and k % ticks_per_cycle == 0 and np.isfinite(run.obs[k, O_HP]).all():
                sl = slice(k - ticks_per_cycle, k + 1)
                idx = indices_from_obs(run.obs[sl], ref.hip[sl], ref.foot[sl],
                                       p.sim.control_period)
                who = run.controller_at(k - 1)
                if run.controller_at(k - ticks_per_cycle) != who:
                    who = "mixed"
                st = indices_status(idx, who, k // ticks_per_cycle - 1,
                                    float(run.t[sl.start]), float(run.t[k]))
                bag.write_diagnostic_array(T.INDICES, stamp, [st])
    return path


__all__ = ["PARAMS_KEY", "RECORDS_KEY", "SIMULATE_NODE", "SIM_NODE", "TICK_TOPICS", "TOPICS",
           "ParamRecorder", "param_status", "indices_status", "params_from_custom_data",
           "status_indices", "write_run_bag"]
