"""What a bag of this project holds, and writing an in-process run in exactly that format.

Both the metrics node and ``hexapod simulate --bag`` record the topics of the one topic table
(``hexapod_common.core.topics.TOPICS``) with its QoS, and score cycles with the one scorer
(``core/cycles.py``); the analysis reads either kind of bag.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from hexapod_control.core.closed_loop import RunResult
from hexapod_common.core import topics as T
from hexapod_common.core.labels import state_frame
from hexapod_common.core.layout import O_HP
from hexapod_common.core.param_log import RECORD_NAME, ParamRecord
from hexapod_common.core.params import SPECS, HexapodParams, from_flat

from hexapod_common.core import cdr
from hexapod_common.core.cdr import DiagnosticStatus

from ..bag import BagWriter
from .cycles import Cycle, CycleScorer, indices_values
from .indices import REPORTED_NAMES, Indices

PARAMS_KEY = "hexapod_params"
#: metadata.yaml custom_data key mirroring the MCAP's parameter records (JSON list of maps).
RECORDS_KEY = "hexapod_parameter_records"
#: The node whose start values are the run's model parameters in metadata.yaml's mirror.
SIM_NODE = "hexapod_sim"
#: The writer of in-process bags, as named in their parameter records.
SIMULATE_NODE = "hexapod simulate"
#: The recorded topics: the one topic table (type, QoS, depth) of ``hexapod_common.core.topics``.
TOPICS = T.TOPICS
TICK_TOPICS = T.TICK_TOPICS


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


def indices_status(cycle: Cycle) -> DiagnosticStatus:
    """One /hexapod/indices status: the seven indices of a scored gait cycle, L, the hip lag
    and its growth since the previous cycle (m per cycle), its label and who was in charge."""
    if cycle.fallen:  # WARN, no indices: the cycle was not a walk
        return DiagnosticStatus(name=f"hexapod/indices/{cycle.controller}",
                                message=f"cycle {cycle.cycle}: {cycle.fallen}",
                                hardware_id="hexapod", level=1, values=indices_values(cycle))
    return DiagnosticStatus(name=f"hexapod/indices/{cycle.controller}",
                            message=f"cycle {cycle.cycle}", hardware_id="hexapod", level=0,
                            values=indices_values(cycle))


def status_indices(status: DiagnosticStatus) -> tuple[Indices, dict[str, str]]:
    """Inverse of :func:`indices_status`: the indices and the other key/values."""
    kv = dict(status.values)
    idx = Indices(**{n: float(kv.pop(n, "nan")) for n in REPORTED_NAMES})
    return idx, kv


#: Chunk size of in-process bags: bigger than the recorder's (``hexapod analyze`` reads 4 MiB
#: chunks 1.5-2x faster than 1 MiB ones); a SIGKILL here ends the run it records anyway.
RUN_BAG_CHUNK = 4 << 20


def write_run_bag(run: RunResult, path: str | Path, chunk_size: int = RUN_BAG_CHUNK) -> Path:
    """Write an in-process run as the graph would record it (every tick of every topic).

    Log time = stamp = simulated time; chunks of ``chunk_size`` bytes. The command of tick k
    answers the state of tick k; each full gait cycle is scored by the one scorer
    (core/cycles.py) from the bytes recorded and its indices are written at its last tick,
    as the metrics node does.
    """
    path = Path(path)
    p = run.params
    ref = run.reference
    n_ticks = run.command.shape[0]
    ticks_per_cycle = int(round(p.cycle_time / p.sim.control_period))
    scorer = CycleScorer(ticks_per_cycle, p.sim.control_period)
    with BagWriter(path, custom_data={"source": SIMULATE_NODE}, chunk_size=chunk_size) as bag:
        for name, spec in TOPICS.items():
            if name not in (T.STATUS, T.MARKERS):  # published by nodes only
                bag.add_topic(name, spec.msg_type, spec.preset)
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
            frame = state_frame(who)  # every torque of an in-process run is commanded
            for topic in T.STATE_TOPICS:
                c = T.state_columns(obs, topic)
                data = cdr.encode_joint_state(stamp, c.names, c.position, c.velocity,
                                              c.effort, frame if topic == T.JOINT_STATES else "")
                bag.write(topic, stamp, data)
                scorer.add_raw(topic, k, data)
            scorer.add_frame(k, frame)
            c = T.reference_columns(ref.theta[k], ref.theta_vel[k], ref.hip[k], ref.hip_vel[k],
                                    ref.foot[k], ref.foot_vel[k])
            data = cdr.encode_joint_state(stamp, c.names, c.position, c.velocity, c.effort)
            bag.write(T.REFERENCE, stamp, data)
            scorer.add_raw(T.REFERENCE, k, data)
            if k < last:
                c = T.command_columns(run.command[k])
                bag.write_joint_state(T.JOINT_COMMANDS, stamp, c.names, c.position, c.velocity,
                                      c.effort, frame_id=who)
            for cycle in scorer.take():
                if cycle.sums is not None and np.isfinite(run.obs[k, O_HP]).all():
                    bag.write_diagnostic_array(T.INDICES, stamp, [indices_status(cycle)])
    return path


__all__ = [
    "PARAMS_KEY",
    "RECORDS_KEY",
    "SIMULATE_NODE",
    "SIM_NODE",
    "TICK_TOPICS",
    "TOPICS",
    "ParamRecorder",
    "indices_status",
    "param_status",
    "params_from_custom_data",
    "status_indices",
    "write_run_bag",
]
