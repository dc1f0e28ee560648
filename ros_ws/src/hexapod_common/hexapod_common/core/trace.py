"""Timestamps of the graph's per-tick work, for the round-trip breakdown (ROS-free).

Off unless ``HEXAPOD_TRACE_DIR`` names a directory in the environment of a node process
(``scripts/bench_graph.py --breakdown`` sets it): then :data:`TRACER` records one row per
event, ``(kind, topic, stamp ns, wall ns, a, b)``, and writes them to
``<dir>/<process>-<pid>.npy`` at exit. Wall times are ``time.time_ns()`` (CLOCK_REALTIME,
the clock of DDS's source and reception timestamps), so events of different processes
line up. Off, every hook costs one ``is None`` test.

Kinds (``a``, ``b`` where used):

* :data:`WAKE` the hot loop's wait returned (``a`` = CPU ns of this thread so far, ``b`` =
  of the whole process: DDS's own threads included);
* :data:`TAKE0` / :data:`TAKE1` before / after ``take_message`` (``a`` = DDS source
  timestamp, ``b`` = DDS reception timestamp of the sample);
* :data:`VERIFIED`, :data:`DECODED`, :data:`CHECKED` the input guard's three stages;
* :data:`SIGN0` / :data:`SIGN1` around ``Signer.sign``; :data:`PUB0` / :data:`PUB1` around a
  ``publish``;
* :data:`STEP0` / :data:`STEP1` around the sim's physics tick; :data:`PREP0` the sim starts
  sampling and serializing a tick; :data:`LAW0` / :data:`LAW1` around the control law.
"""
from __future__ import annotations

import atexit
import os
import struct
import sys
import time
from pathlib import Path

import numpy as np

from hexapod_common.core import topics as T

TRACE_ENV = "HEXAPOD_TRACE_DIR"
(WAKE, TAKE0, TAKE1, VERIFIED, DECODED, CHECKED, SIGN0, SIGN1, PUB0, PUB1, STEP0, STEP1,
 PREP0, LAW0, LAW1) = range(15)
KINDS = ("wake", "take0", "take1", "verified", "decoded", "checked", "sign0", "sign1", "pub0",
         "pub1", "step0", "step1", "prep0", "law0", "law1")
#: Topic ids of the trace (index + 1; 0 = none or another topic).
TOPICS = (T.JOINT_STATES, T.FOOT_FORCES, T.HIP_STATES, T.REFERENCE, T.JOINT_COMMANDS, T.CLOCK,
          T.ACTIVE_CONTROLLER, T.STATUS, T.INDICES, T.MARKERS, T.PARAMETERS)
TOPIC_ID = {t: i + 1 for i, t in enumerate(TOPICS)}
MAX_ROWS = 4_000_000  # ~200 MB of rows at most per process
_STAMP = struct.Struct("<iI")


def header_stamp(data: bytes) -> int:
    """Stamp (ns) of a serialized message that starts with a std_msgs/Header; -1 if short."""
    if len(data) < 12:
        return -1
    sec, nsec = _STAMP.unpack_from(data, 4)
    return int(sec) * 1_000_000_000 + int(nsec)


class Tracer:
    """Collects event rows in memory; :meth:`save` writes them as an (n, 6) int64 array."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.rows: list[tuple[int, int, int, int, int, int]] = []

    def mark(self, kind: int, topic: str = "", stamp: int = -1, a: int = 0, b: int = 0
             ) -> None:
        """Record one event now."""
        if len(self.rows) < MAX_ROWS:
            self.rows.append((kind, TOPIC_ID.get(topic, 0), stamp, time.time_ns(), a, b))

    def wake(self) -> None:
        """The hot loop woke up (with this thread's CPU time so far)."""
        if len(self.rows) < MAX_ROWS:
            self.rows.append((WAKE, 0, -1, time.time_ns(), time.thread_time_ns(),
                              time.process_time_ns()))

    def taken(self, topic: str, t0: int, data: bytes, info: dict[str, int | None]) -> None:
        """A sample taken: TAKE0 at ``t0`` and TAKE1 now, with its DDS timestamps."""
        if len(self.rows) < MAX_ROWS - 1:
            tid, stamp = TOPIC_ID.get(topic, 0), header_stamp(data)
            self.rows.append((TAKE0, tid, stamp, t0, 0, 0))
            self.rows.append((TAKE1, tid, stamp, time.time_ns(),
                              int(info.get("source_timestamp") or 0),
                              int(info.get("received_timestamp") or 0)))

    def save(self) -> None:
        """Write the rows to :attr:`path` (best effort: a trace never fails a node)."""
        try:
            np.save(self.path, np.array(self.rows, dtype=np.int64).reshape(-1, 6))
        except OSError as err:
            print(f"trace: cannot write {self.path}: {err}", file=sys.stderr)


def _from_env() -> Tracer | None:
    folder = os.environ.get(TRACE_ENV, "")
    if not folder:
        return None
    name = Path(sys.argv[0]).name if sys.argv and sys.argv[0] not in ("", "-c") else "node"
    tracer = Tracer(Path(folder) / f"{name}-{os.getpid()}.npy")
    atexit.register(tracer.save)
    return tracer


#: The process's tracer, or None (tracing off).
TRACER: Tracer | None = _from_env()


def name_process(name: str) -> None:
    """Name this process's trace file after its node (call once, at node start). A node
    forked from a server that imported this module without ``HEXAPOD_TRACE_DIR`` (the
    graph's fork server) gets its tracer here, from its own environment."""
    global TRACER
    if TRACER is None:
        TRACER = _from_env()
    if TRACER is not None:
        TRACER.path = TRACER.path.with_name(f"{name}-{os.getpid()}.npy")


__all__ = ["KINDS", "TOPICS", "TOPIC_ID", "TRACER", "TRACE_ENV", "Tracer", "header_stamp",
           "name_process"]
