"""The round-trip breakdown (hexapod_common.core.trace_breakdown) on traces with known timing:
every segment comes out at its planted length and the segments add up to the period."""
import os
import subprocess
import sys

import numpy as np
import pytest
from hexapod_common.core import topics as T
from hexapod_common.core import trace as tr
from hexapod_common.core.trace_breakdown import ROUND_TRIP, SEGMENTS, breakdown, load

TICK_NS = 1_000_000      # stamps: 1 kHz
PERIOD = 10_000          # wall ns per tick in the planted traces
N = 150
ID = tr.TOPIC_ID
# planted lengths (ns) of the segments, in SEGMENTS order; the last one fills the period
PLANTED = [50, 150, 50, 50, 100, 100, 100, 100, 200, 100, 100, 100, 100, 100, 100, 100, 100,
           100, 100, 100, 100, 100, 100, 200, 150]
PLANTED.append(PERIOD - sum(PLANTED))


def _reception(topic, s, t, marks, dds):
    """Take, taken (with the DDS source and reception stamps), verified, decoded, checked
    of one message of ``topic`` stamped ``s``, at wall offsets ``marks`` from ``t``."""
    take0, take1, verified, decoded, checked = (t + m for m in marks)
    return [(tr.TAKE0, ID[topic], s, take0, 0, 0),
            (tr.TAKE1, ID[topic], s, take1, t + dds[0], t + dds[1]),
            (tr.VERIFIED, ID[topic], s, verified, 0, 0),
            (tr.DECODED, ID[topic], s, decoded, 0, 0),
            (tr.CHECKED, ID[topic], s, checked, 0, 0)]


def _traces():
    sim, ctrl, idle = [], [], []
    for k in range(N):
        s, t = k * TICK_NS, k * PERIOD
        c = np.cumsum([0] + PLANTED)  # boundaries relative to t
        sim += [(tr.PUB0, 0, s, t + c[0], 0, 0), (tr.PUB1, ID[T.FOOT_FORCES], s, t + 20, 0, 0),
                (tr.PUB1, ID[T.JOINT_STATES], s, t + c[1] + 10, 0, 0)]
        ctrl += [(tr.WAKE, 0, -1, t + c[3], 300_000 * k, 400_000 * k),
                 *_reception(T.JOINT_STATES, s, t, c[4:9], c[1:3]),
                 (tr.LAW0, 0, s, t + c[9], 0, 0), (tr.LAW1, 0, s, t + c[10], 0, 0),
                 (tr.SIGN0, ID[T.JOINT_COMMANDS], s, t + c[11], 0, 0),
                 (tr.SIGN1, ID[T.JOINT_COMMANDS], -1, t + c[11] + 40, 0, 0),
                 (tr.PUB0, ID[T.JOINT_COMMANDS], s, t + c[12], 0, 0)]
        idle.append((tr.WAKE, 0, -1, t + 5, 100_000 * k, 150_000 * k))
        sim += [(tr.WAKE, 0, -1, t + c[15], 500_000 * k, 700_000 * k),
                *_reception(T.JOINT_COMMANDS, s, t, c[16:21], c[13:15]),
                (tr.STEP0, 0, s, t + c[21], 0, 0), (tr.STEP1, 0, s, t + c[22], 0, 0),
                (tr.PREP0, 0, -1, t + c[23], 0, 0)]
        # the next tick's three state messages: encode 200 ns in all, sign 150 ns in all
        a = t + c[23]
        for topic, enc, sig in ((T.FOOT_FORCES, 100, 50), (T.JOINT_STATES, 50, 50),
                                (T.HIP_STATES, 50, 50)):
            sim += [(tr.SIGN0, ID[topic], s + TICK_NS, a + enc, 0, 0),
                    (tr.SIGN1, ID[topic], -1, a + enc + sig, 0, 0)]
            a += enc + sig
    return {"hexapod_sim": np.array(sim, dtype=np.int64),
            "pd_pf_controller": np.array(ctrl, dtype=np.int64),
            "pd_p_controller": np.array(idle, dtype=np.int64)}


def test_breakdown_recovers_planted_segments_and_adds_up_to_the_period():
    b = breakdown(_traces(), "pd_pf", skip=10)
    assert len(SEGMENTS) == len(PLANTED)
    assert b.ticks == N - 11  # the last tick has no successor
    assert b.median_ms == pytest.approx([x / 1e6 for x in PLANTED], abs=1e-12)
    assert b.period_median_ms == pytest.approx(PERIOD / 1e6)
    assert b.round_trip_median_ms == pytest.approx(
        sum(PLANTED[ROUND_TRIP[0]:ROUND_TRIP[1]]) / 1e6)
    assert b.cpu_per_tick_ms["pd_pf_controller"] == pytest.approx(0.3)
    assert b.other_cpu_per_tick_ms["pd_pf_controller"] == pytest.approx(0.1)
    assert b.cpu_per_tick_ms["pd_p_controller"] == pytest.approx(0.1)
    assert b.cpu_per_tick_ms["hexapod_sim"] == pytest.approx(0.5)


def test_breakdown_refuses_a_trace_without_the_controller_in_charge():
    traces = _traces()
    with pytest.raises(ValueError, match="no tick has every timestamp"):
        breakdown(traces, "pd_p")  # the idle controller answered nothing
    del traces["pd_pf_controller"]
    with pytest.raises(KeyError):
        breakdown(traces, "pd_pf")


def test_a_traced_process_writes_its_rows_at_exit_and_none_without_the_variable(tmp_path):
    code = ("from hexapod_common.core import trace as t; t.name_process('probe'); "
            "t.TRACER.mark(t.LAW0, '/hexapod/joint_commands', 7); t.TRACER.wake()")
    subprocess.run([sys.executable, "-c", code], check=True,
                   env={**os.environ, tr.TRACE_ENV: str(tmp_path)})
    rows = load(tmp_path)["probe"]
    assert rows.shape == (2, 6)
    assert list(rows[0, :3]) == [tr.LAW0, ID[T.JOINT_COMMANDS], 7]
    assert rows[1, 0] == tr.WAKE and rows[1, 5] >= rows[1, 4] > 0
    off = subprocess.run([sys.executable, "-c",
                          "from hexapod_common.core import trace as t; print(t.TRACER)"],
                         check=True, capture_output=True, text=True,
                         env={k: v for k, v in os.environ.items()
                              if k != tr.TRACE_ENV})
    assert off.stdout.strip() == "None"


def test_a_node_forked_from_a_server_without_the_variable_traces_from_its_own_environment(
        tmp_path):
    # The graph's fork server imports trace before any node's environment is known (the
    # nodes' environments are set after the fork): naming the process creates its tracer.
    code = ("import os; from hexapod_common.core import trace as t; assert t.TRACER is None; "
            f"os.environ[{tr.TRACE_ENV!r}] = {str(tmp_path)!r}; t.name_process('forked'); "
            "t.TRACER.mark(t.LAW0, '/hexapod/joint_commands', 9)")
    subprocess.run([sys.executable, "-c", code], check=True,
                   env={k: v for k, v in os.environ.items() if k != tr.TRACE_ENV})
    rows = load(tmp_path)["forked"]
    assert rows.shape == (1, 6) and list(rows[0, :3]) == [tr.LAW0, ID[T.JOINT_COMMANDS], 9]


def test_an_unwritable_trace_folder_costs_one_line_and_not_the_run(tmp_path):
    missing = tmp_path / "no" / "such" / "folder"
    code = ("from hexapod_common.core import trace as t; t.name_process('probe'); "
            "t.TRACER.mark(t.LAW0, '/hexapod/joint_commands', 7); print('ran')")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       env={**os.environ, tr.TRACE_ENV: str(missing)})
    assert r.returncode == 0 and r.stdout.strip() == "ran"
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"trace: cannot write {missing}")
