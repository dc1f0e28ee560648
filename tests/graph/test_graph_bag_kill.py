"""A recorder killed with SIGKILL at several points leaves indexed, ordered bags (R11).

One graph runs; three recorders join it one after another and are killed at different
points (between two chunk writes): the first (there from tick 0) right after its first
chunk, the two that join
mid-run after ~12 and ~16 MB (their first ~10 MB are the transient-local history of the
reference and the commands, 5000 ticks each, older than any joint state they get). Every
bag must open in the mcap library's seeking reader and in rosbags (indexed: a summary),
hold its tick topics in log-time order without gaps (the commands may lack the ticks the
sim counted as missed; a recorder that joined mid-run may have holes in its first
0.5 s of states and in the backlog before them: ``check_indexed_ordered_bag``), end them
all at the same tick, agree with metadata.yaml up to the
last chunk, and be reported truncated by ``hexapod analyze``.
"""
from __future__ import annotations

import signal
import time

from hexapod_metrics.core.analysis import analyze_bag
from hexapod_metrics.bag import open_bag
from hexapod_common.core import topics as T

from .bag_checks import check_indexed_ordered_bag, mcap_size
from .conftest import sim_summary

#: Bytes a killed recorder's MCAP must have grown past its empty start before the kill.
KILL_AFTER = (1, 12_000_000, 16_000_000)


def _settled(bag, quiet: float = 0.05) -> bool:
    """The MCAP's size did not change for ``quiet`` s (no chunk being written)."""
    before = mcap_size(bag)
    time.sleep(quiet)
    return mcap_size(bag) == before


def _has_chunk(bag) -> bool:
    """The MCAP's summary (as the mcap library reads it now) indexes at least one chunk.
    Growth alone does not say so: a topic's first message writes its schema and channel
    records before any chunk, and a kill right then left the first bag without a message
    (seen once in the full suite on a loaded machine)."""
    from mcap.reader import SeekingReader

    from .bag_checks import mcap_file

    try:
        with open(mcap_file(bag), "rb") as fh:
            summary = SeekingReader(fh).get_summary()
    except Exception:  # noqa: BLE001 - a tail being rewritten reads as anything
        return False
    return summary is not None and len(summary.chunk_indexes) > 0


def test_killed_recorders_leave_indexed_ordered_bags(make_graph, tmp_path):
    g = make_graph()
    g.start("metrics", f"bag_path:={tmp_path / 'first'}", node="metrics")
    g.start("trajectory_generator")
    g.start("pd_pf_controller")
    g.start("hexapod_sim", "wait_for:=trajectory_generator,pd_pf_controller,metrics")
    g.wait_log("hexapod_sim", "Hz control", timeout=180)
    bags = []
    for i, grow in enumerate(KILL_AFTER):
        bag = tmp_path / ("first" if i == 0 else f"kill{i}")
        if i:
            g.start("metrics", f"bag_path:={bag}", node="metrics")
        g.wait_for(lambda bag=bag: mcap_size(bag) > 0, 120, f"{bag.name} created")
        empty = mcap_size(bag)
        g.wait_for(lambda bag=bag, empty=empty, grow=grow: mcap_size(bag) >= empty + grow
                   and _has_chunk(bag), 180, f"{bag.name} grown by {grow} bytes, a chunk")
        # Between two chunk writes: a kill inside the pwrite of a chunk and its tail tears
        # the file for every reader but ours (README, "What a recording leaves behind"),
        # and a recorder that joined late writes its backlog back to back for a while.
        g.wait_for(lambda bag=bag: _settled(bag), 180, f"{bag.name} between two writes")
        assert g.kill("metrics", signal.SIGKILL) == -signal.SIGKILL
        bags.append(bag)
    assert g.procs["hexapod_sim"].poll() is None  # the graph went on without its recorders
    g.stop("hexapod_sim")
    missed = sim_summary(g.log("hexapod_sim"))["missed"]  # a loaded machine may miss ticks

    for i, bag in enumerate(bags):
        stamps = check_indexed_ordered_bag(bag, missed, joined_late=i > 0)
        n = len(stamps[T.JOINT_STATES])
        assert n > 0
        with open_bag(bag) as b:  # our reader: indexed, but the writer never closed it
            assert b.truncated and "not closed" in b.truncation_reason
            assert b.topics[T.JOINT_STATES].message_count == n
        a = analyze_bag(bag)
        assert a.truncated
        assert a.ticks <= n
        # a cycle is scored only if all its ticks are in the bag
        last = stamps[T.JOINT_STATES][-1] * 1e-9
        assert all(c.t_b <= last + 1e-9 for c in a.cycles)
