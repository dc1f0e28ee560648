"""Node ``metrics``: records every topic of the contract to a bag and scores each gait cycle.

Every topic is taken raw, authenticated and checked (``hexapod_common.runtime.input_guard``: a
dropped message is counted and reported, never recorded) and its payload written to a
rosbag2/MCAP bag (:class:`~hexapod_metrics.bag.BagWriter`) at ``bag_path`` with the topic
table's QoS; ``/clock`` is written from the authenticated joint states. Log time = the
message's own sim time (:mod:`~hexapod_metrics.core.log_times`); chunks are cut at a
watermark over the tick topics, so a SIGKILL leaves an indexed bag whose topics all end at
the same tick. Parameters (start values and runtime changes, from ``/hexapod/parameters``)
go into the MCAP as checksummed metadata (``core/recording.py``). A failed write (full
disk) closes the bag at its last chunk, reports ERROR on ``/hexapod/status`` and exits
with :data:`EXIT_RECORDING_FAILED` (3); 0 clean, 1 other error, 2 bad parameters. Each gait
cycle is scored by :mod:`~hexapod_metrics.core.cycles`, published on ``/hexapod/indices``
with its label (``hexapod_common.core.labels``) and listed in ``indices.json`` at close.
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from hexapod_common.core import msg_checks as M
from hexapod_common.core import topics as T
from hexapod_common.core.labels import in_charge
from hexapod_common.core.param_log import RECORD_NAME, ParamRecord, timeline
from hexapod_common.core.params import SPECS
from hexapod_common.runtime.controller_graph import NamesOnGraph
from hexapod_common.core.topics import TICK_TOPICS, TOPICS
from hexapod_common.runtime.hot_loop import FastLogger, HotLoop
from hexapod_common.runtime.input_guard import InputGuard
from hexapod_common.runtime.node_main import run_node
from hexapod_common.runtime.param_topic import ParamAnnouncer
from hexapod_common.runtime.ros_params import ParamBinding, declare_node_param, declare_params
from hexapod_common.runtime.rt_sched import use_rt_priority
from rclpy.duration import Duration
from rclpy.node import Node

from hexapod_common.runtime import conversions as C
from hexapod_common.runtime import inputs_matched
from hexapod_common.core import cdr
from hexapod_common.core.errors import CdrError

from .bag import BagError, BagStorageError, BagWriter
from .core.cycles import CYCLE_TOPICS, Cycle, CycleScorer, segments
from .core.indices import INDEX_NAMES, REPORTED_NAMES
from .core.log_times import ControllerLogTimes, marker_array_stamp
from .core.recording import ParamRecorder, indices_status
from .core.walking import not_walking

#: Exit code of a recorder whose bag could not be written to the end (disk full, ...).
EXIT_RECORDING_FAILED = 3


class MetricsNode(Node):
    """Recorder and online scorer."""

    def __init__(self) -> None:
        super().__init__("metrics")
        self.log = FastLogger(self.get_logger().name)
        self.guard = InputGuard(self, self.log)  # nothing unauthenticated or malformed is recorded
        # The states are the time source; nothing far ahead of them is recorded. The recorder
        # takes its queues in batches, topic by topic, and may lag by seconds: the window is
        # wide (a stamp of 1e6 s, which once made the scorer skip a million cycles, is not).
        self.window = M.StampWindow(ahead_s=60.0)
        # /hexapod/active_controller names a controller (the naming rule) that is built in,
        # whose node is on the graph, or that the sim's states name (_on_controller)
        self.controller_names = NamesOnGraph(self)
        self.any_controller = NamesOnGraph(self, on_graph=False)
        # (name, payload, newest state stamp when it came): announcements decided at the
        # states (a joined controller in charge from tick 0 is announced before this node
        # may have discovered it)
        self.undecided: list[tuple[str, bytes, int]] = []
        self.binding = ParamBinding(self, declare_params(self))
        p = self.binding.params
        default = "bags/" + time.strftime("%Y%m%d-%H%M%S")
        self.bag_path = Path(declare_node_param(self, "bag_path") or default)
        batch = declare_node_param(self, "batch_interval")
        window = declare_node_param(self, "reorder_window")
        max_size = declare_node_param(self, "max_bag_size")
        max_duration = declare_node_param(self, "max_bag_duration")
        # Its Fast DDS threads under SCHED_FIFO when asked (the launcher does in realtime
        # mode: runtime/rt_sched.py); the main thread keeps normal scheduling.
        self.rt = use_rt_priority(self, self.log, main=False)
        self.period = p.sim.control_period
        # The recorder takes its queues topic by topic and may lag by seconds: a cycle waits
        # for its slowest topic (as offline), and is given up only if a topic stays 10 cycles
        # behind the others (dead; memory stays bounded).
        n = int(round(p.cycle_time / self.period))
        gap = 10 * n
        self.scorer = CycleScorer(n, self.period, gap_ticks=gap,
                                  walk=lambda sums: not_walking(sums, p))
        self.writer = BagWriter(self.bag_path, custom_data={"source": "metrics node"},
                                flush_interval_s=0.5, sync_topics=TICK_TOPICS,
                                follow_topics=(T.MARKERS,),
                                reorder_window_ns=int(window * 1e9),
                                # a tick topic is given up as dead when the scorer gives up
                                # its cycles: a live one the recorder fell seconds behind on
                                # still holds the chunks, so a kill leaves every tick topic
                                # ending at the same tick (R11; 2 s was too short: seen once
                                # in the suite, a late-joining recorder's states 2 s behind)
                                max_lag_ns=int(round(gap * self.period * 1e9)),
                                max_file_size=int(max_size),
                                max_file_duration_ns=int(max_duration * 1e9))
        self.writer.open()
        self.params_log = ParamRecorder(self.writer)
        self.bad_param_records = 0
        self.failure: BagStorageError | None = None
        self.dropped = 0  # messages received after the recording failed
        self.controller_times = ControllerLogTimes()
        for topic, spec in TOPICS.items():
            self.writer.add_topic(topic, spec.msg_type, spec.preset)
        self.clock_ns = 0
        self.counts = {t: 0 for t in TOPICS}
        self.guard.publish_status(self.get_name(), lambda: self.clock_ns)
        self.loop = HotLoop(self, batch_interval=batch)
        inputs_matched.offer(self, self.loop.subscriptions, self.guard)  # asked before tick 0
        self.pub_indices = self.create_publisher(DiagnosticArray, T.INDICES,
                                                 C.TOPIC_QOS[T.INDICES].publisher())
        self.pub_status = self.create_publisher(DiagnosticArray, T.STATUS,
                                                C.TOPIC_QOS[T.STATUS].publisher())
        self.indices_signer = self.guard.signer(T.INDICES)
        # How far the bag goes, for the sim's lockstep pacing (hexapod_sim/core/recorder_pace.py)
        self.pub_recorded = self.create_publisher(DiagnosticArray, T.RECORDED,
                                                  C.RECORDED_QOS.publisher())
        self.recorded_signer = self.guard.signer(T.RECORDED)
        self.next_recorded = 0  # the tick of the next /hexapod/recorded
        # /clock is not subscribed: it carries no tag (a bounded type, see sim_node.py);
        # the clock of each tick is written from the authenticated joint states.
        for topic in TOPICS:
            if topic in (T.INDICES, T.CLOCK, T.JOINT_STATES):
                continue
            self._subscribe(topic)
        self._subscribe(T.JOINT_STATES)  # last: the sim waits for it before tick 0
        self.announcer = ParamAnnouncer(self, self.period, lambda: self.scorer.latest + 1)
        self.log.info(f"recording to {self.bag_path}")

    def _write(self, topic: str, log_time: int, data: bytes) -> None:
        """Record one message; a failed write ends the recording (see the module doc)."""
        if self.failure is not None:
            self.dropped += 1
            return
        try:
            self.writer.write(topic, log_time, data)
        except BagStorageError as err:
            self.failure = err
            self.loop.stop()
            return
        self.counts[topic] += 1

    def _say_recorded(self, stamp: int, tick: int) -> None:
        """Publish how far the bag goes (the newest joint state written: ``stamp``, ``tick``)."""
        if self.failure is not None:
            return
        self.pub_recorded.publish(self.recorded_signer.sign(
            cdr.encode_diagnostic_array(stamp, [])))
        self.next_recorded = tick + T.RECORDED_EVERY

    def _write_controller(self, items: list[tuple[int, bytes]]) -> None:
        for log_time, data in items:
            self._write(T.ACTIVE_CONTROLLER, log_time, data)
            self.log.info(f"controller in charge: {C.decode_string(data)} "
                          f"(from sim time {log_time * 1e-9:.3f} s)")

    def _on_controller(self, payload: bytes, name: str) -> None:
        """An authentic announcement of the controller in charge: recorded if it is built in,
        its node is on the graph or the states name it; else decided at the next states."""
        if name in self.controller_names or name == self.controller_times.frame:
            self._write_controller(self.controller_times.on_controller(name, payload))
        else:
            self.undecided.append((name, payload, self.clock_ns))

    def _decide_controllers(self, stamp: int, frame: str | None) -> None:
        """Record the undecided announcements that the states (``frame``: the controller in
        charge at ``stamp``) or the graph now vouch for; drop those neither did within
        ControllerLogTimes' patience (1 s of simulated time), counted as bad content."""
        keep = []
        for name, payload, since in self.undecided:
            if name == frame or name in self.controller_names:
                self._write_controller(self.controller_times.on_controller(name, payload))
            elif stamp - since > self.controller_times.patience:
                self.guard.drop(T.ACTIVE_CONTROLLER, M.BAD_CONTENT,
                                f"{name!r} is none of the controllers on the graph")
            else:
                keep.append((name, payload, since))
        self.undecided = keep

    def _subscribe(self, topic: str) -> None:
        # Every message is authenticated and checked by the guard first (a dropped one is
        # counted and reported, never recorded); the bag gets the payload without trailer.
        q = C.TOPIC_QOS[topic]
        g = self.guard
        period_ns = int(round(self.period * 1e9))
        if topic in CYCLE_TOPICS or topic == T.JOINT_COMMANDS:
            def cb(data: bytes, topic: str = topic) -> None:
                got = g.joint_state_payload(topic, data, period_ns, self.window,
                                            topic == T.JOINT_STATES)
                if got is None:
                    return
                payload, view = got
                stamp = view.stamp_ns
                tick = C.tick_of(stamp, period_ns)
                if topic == T.JOINT_STATES:
                    self.clock_ns = max(self.clock_ns, stamp)
                    self._write(T.CLOCK, stamp, C.encode_clock(stamp))
                self._write(topic, stamp, payload)
                if topic == T.JOINT_STATES:
                    if self.undecided:
                        self._decide_controllers(stamp, in_charge(view.frame_id))
                    self._write_controller(self.controller_times.on_state(
                        stamp, in_charge(view.frame_id)))
                    if tick >= self.next_recorded:
                        self._say_recorded(stamp, tick)
                if topic in CYCLE_TOPICS:
                    if topic == T.JOINT_STATES:
                        self.scorer.add_frame(tick, view.frame_id)
                    self.scorer.add_raw(topic, tick, payload)
                    for cycle in self.scorer.take():
                        if cycle.sums is not None:  # a gap (not in lockstep): no indices
                            self._publish_cycle(cycle)
        elif topic == T.MARKERS:  # the first marker's stamp (the latest clock if empty)
            def cb(data: bytes, topic: str = topic) -> None:
                payload = g.payload(topic, data)
                if payload is None:
                    return
                stamp = marker_array_stamp(payload)
                self._write(topic, self.clock_ns if stamp is None else stamp, payload)
        elif topic == T.PARAMETERS:
            cb = self._on_param_record
        elif topic == T.ACTIVE_CONTROLLER:  # at the tick the switch took effect
            def cb(data: bytes, topic: str = topic) -> None:
                got = g.string(topic, data, self.any_controller)
                if got is not None:
                    self._on_controller(*got)
        else:  # status (diagnostic arrays of the graph's nodes)
            def cb(data: bytes, topic: str = topic) -> None:
                payload = g.payload(topic, data)
                if payload is None:
                    return
                try:
                    stamp, _ = cdr.decode_diagnostic_array(payload)
                    self.window.check(stamp)
                except CdrError as err:
                    g.drop(topic, M.UNDECODABLE, str(err))
                    return
                except M.Dropped as d:
                    g.drop(topic, d.cause, d.detail)
                    return
                self._write(topic, stamp, payload)
        # commands: volatile, so that a controller publishing with rclpy's defaults is heard
        self.loop.subscribe(q.msg_type, topic, cb, q.volatile_subscriber(C.RECORD_DEPTH)
                            if topic == T.JOINT_COMMANDS else q.subscriber(C.RECORD_DEPTH))

    def _on_param_record(self, data: bytes) -> None:
        """A node's parameter record: into the bag (message, MCAP metadata, mirror)."""
        payload = self.guard.payload(T.PARAMETERS, data)  # the graph's own nodes only
        if payload is None:
            return
        self.counts[T.PARAMETERS] += 1
        try:
            _, sts = cdr.decode_diagnostic_array(payload)  # as the offline analysis reads them
            recs = [ParamRecord.from_map(dict(st.values), f"parameter record '{st.name}'")
                    for st in sts if st.name.startswith(RECORD_NAME + "/")]
        except Exception as err:  # noqa: BLE001 - anything undecodable is dropped, counted
            self.bad_param_records += 1
            self.log.warning(f"dropped a {T.PARAMETERS} message ({self.bad_param_records} so "
                             f"far): {str(err).splitlines()[0] if str(err) else err!r}")
            return
        for rec in recs:
            if self.failure is not None:
                self.dropped += 1
                return
            try:
                added = self.params_log.add(rec, payload if len(recs) == 1 else None)
            except BagStorageError as err:
                self.failure = err
                self.loop.stop()
                return
            if added:
                what = "start values" if rec.kind == "start" else \
                    ", ".join(f"{k} = {v!r}" for k, v in rec.values.items())
                self.log.info(f"parameters of {rec.node} at tick {rec.tick}: {what}")

    def _publish_cycle(self, cycle: Cycle) -> None:
        idx = cycle.indices
        stamp = T.stamp_ns(cycle.t_b)
        data = cdr.encode_diagnostic_array(stamp, [indices_status(cycle)])
        self.pub_indices.publish(self.indices_signer.sign(data))
        self._write(T.INDICES, stamp, data)
        if idx is None:
            self.log.warning(f"cycle {cycle.cycle} [{cycle.t_a:g}, {cycle.t_b:g}] s "
                             f"({cycle.in_charge}): {cycle.fallen}; no indices")
            return
        self.log.info(
            f"cycle {cycle.cycle} [{cycle.t_a:g}, {cycle.t_b:g}] s ({cycle.controller}): "
            + ", ".join(f"{n} {getattr(idx, n):.4g}" for n in INDEX_NAMES)
            + f"; hip lag {idx.lag_xH:.4g} m ({cycle.lag_growth:+.3g} m since the last "
            "cycle)")

    def scores(self) -> dict[str, Any]:
        """Every scored cycle and, per controller segment, the cycles it fully commanded and
        the last of them (indices.json)."""
        sc = self.scorer
        done = [c for c in sc.cycles if c.sums is not None]
        return {"control_period": self.period, "ticks_per_cycle": sc.n,
                "index_names": list(REPORTED_NAMES),
                "segments": segments(done, sc.labels.history, self.period, sc.last_state),
                "cycles": [c.as_dict() for c in done]}

    def close(self) -> None:
        """Take what is queued, close the bag, write indices.json; idempotent."""
        if self.closed:
            return
        self.closed = True
        try:
            if self.failure is None:
                self.loop.drain()
                for name, _, _ in self.undecided:  # never named by the states
                    self.guard.drop(T.ACTIVE_CONTROLLER, M.BAD_CONTENT,
                                    f"{name!r} is none of the controllers on the graph")
                self.undecided = []
                self._write_controller(self.controller_times.flush())
            self.lost_in_transit = self.guard.missing()
        finally:
            try:
                self.writer.close()
            except BagStorageError as err:  # the last chunk did not fit
                self.failure = err
        report = {"bag": str(self.bag_path), "messages": self.counts,
                  "dropped_parameter_messages": self.bad_param_records,
                  "parameter_records": len(self.params_log.records),
                  "dropped": {f"{t} ({c})": n for (t, c), n in self.guard.drops.counts.items()},
                  "outside_publishers": {t: sorted(n) for t, n in self.guard.outsiders.items()},
                  "parameter_changes": self.parameter_changes(),
                  **self.scores(),
                  "recording": self.recording_report()}
        try:
            (self.bag_path / "indices.json").write_text(json.dumps(report, indent=1))
        except OSError as err:
            self.log.error(f"cannot write indices.json: {err.strerror}")
        if self.failure is not None:
            self.report_failure()
            return
        if self.lost_in_transit:  # said, not an error: any holder of the key can make holes
            self.log.warning(
                f"{sum(self.lost_in_transit.values())} authentic messages never reached "
                "the recorder (" + ", ".join(f"{t} {n}" for t, n in
                                             sorted(self.lost_in_transit.items()))
                + "): the bag lacks them. A recorder starved of CPU (on a busy machine, or "
                "beside a lockstep control path under SCHED_FIFO) lets its queues overflow; "
                "a sender holding the run's key may also have skipped numbers")
        late = self.writer.late_messages
        self.log.info(
            f"bag closed: {self.bag_path} ({sum(self.counts.values())} messages, "
            f"{sum(c.sums is not None for c in self.scorer.cycles)} cycles scored"
            + (f", {late} came in after their chunk" if late else "") + ")"
            + f"; inputs: {self.guard.summary()}")

    closed = False
    #: topic -> messages that never reached this node (known once closed; empty with
    #: authentication off, which has no sequence numbers to tell)
    lost_in_transit: dict[str, int] = {}

    def parameter_changes(self) -> list[dict[str, Any]]:
        """The live changes of model parameters recorded, each from its owner (the node that
        applies it), at the tick it took effect (indices.json)."""
        tl = timeline(self.params_log.records, SPECS)
        return [{"tick": k, "t": k * self.period, "node": node, "name": name, "value": v}
                for k, node, name, v in (tl.changes if tl is not None else ())
                if name != "run.controller"]  # switches split the segments already

    def recording_report(self) -> dict[str, Any]:
        """How the recording ended: state, failure, late and lost messages."""
        return {"state": "failed" if self.failure else "closed",
                "failure": str(self.failure) if self.failure else "",
                "late_messages": self.writer.late_messages,
                "lost_in_transit": self.lost_in_transit,
                "lost_messages": self.writer.lost_messages + self.dropped,
                "unmatched_controller_messages": self.controller_times.unmatched}

    def report_failure(self) -> None:
        """Say on /hexapod/status and in the log that the recording stopped, and why."""
        err = self.failure
        assert err is not None
        values = {"bag": str(self.bag_path), "reason": err.reason,
                  "sim_time": f"{self.clock_ns * 1e-9:.6f}",
                  "messages_written": str(sum(self.counts.values())),
                  "messages_lost": str(self.writer.lost_messages + self.dropped),
                  "exit_code": str(EXIT_RECORDING_FAILED)}
        status = C.Status("metrics", "error", f"recording stopped: {err}", values)
        self.pub_status.publish(self.guard.signed(self.guard.signer(T.STATUS),
                                                  C.encode_statuses(self.clock_ns, [status])))
        self.pub_status.wait_for_all_acked(Duration(seconds=2))
        self.log.error(f"recording stopped at sim time {self.clock_ns * 1e-9:.3f} s: {err}")


def _finish(node: MetricsNode, code: int) -> int:
    """Close the bag and write indices.json; a recording that failed exits 3."""
    node.close()
    return EXIT_RECORDING_FAILED if node.failure is not None else code


def main(args: list[str] | None = None) -> int:
    """Entry point of ``metrics``."""
    return run_node("metrics", MetricsNode, args, finish=_finish, errors=(BagError,))


if __name__ == "__main__":
    sys.exit(main())
