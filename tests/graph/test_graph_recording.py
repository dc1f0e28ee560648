"""The recorder stopped by SIGTERM closes its bag; killed by SIGKILL it leaves a readable one."""
from __future__ import annotations

import signal
from pathlib import Path

import numpy as np

from hexapod_metrics.bag import open_bag, read_joint_state_arrays
from hexapod_common.core import topics as T


def _mcap_size(bag: Path) -> int:
    files = list(bag.glob("*.mcap"))
    return files[0].stat().st_size if files else 0


def _contiguous(stamps: np.ndarray) -> bool:
    return bool(len(stamps) > 1 and np.all(np.diff(stamps) == 1_000_000))


def test_recorder_stopped_or_killed_leaves_a_readable_bag(make_graph, tmp_path):
    g = make_graph()
    term_bag, kill_bag = tmp_path / "term", tmp_path / "kill"
    g.start("metrics", f"bag_path:={term_bag}")
    g.start("trajectory_generator")
    g.start("pd_pf_controller")
    g.start("hexapod_sim", "wait_for:=trajectory_generator,pd_pf_controller,metrics")
    g.wait_log("metrics", "cycle 1 ", timeout=120)  # two gait cycles recorded

    # SIGTERM: clean close, summary and metadata written, every received tick in the bag.
    assert g.kill("metrics", signal.SIGTERM) == 0
    assert "bag closed" in g.log("metrics")
    with open_bag(term_bag) as bag:
        assert not bag.truncated
        js = read_joint_state_arrays(bag, T.JOINT_STATES)
    assert len(js.stamps) >= 2001 and js.stamps[0] == 0 and _contiguous(js.stamps)
    assert (term_bag / "indices.json").exists()
    from rosbags.highlevel import AnyReader

    with AnyReader([term_bag]) as reader:
        n = sum(1 for c, _, _ in reader.messages() if c.topic == T.JOINT_STATES)
    assert n == len(js.stamps)

    # SIGKILL of a second recorder that joined mid-run: the flushed chunks stay readable.
    g.start("metrics", f"bag_path:={kill_bag}", node="metrics")
    part = "recording to " + str(kill_bag)
    # three cycles scored: the flushed prefix (behind the reorder window and the open
    # chunk) then holds more than one cycle of ticks
    g.wait_for(lambda: part in g.log("metrics")
               and g.log("metrics").split(part)[-1].count(" cycle ") >= 3, 180,
               "three gait cycles scored by the second recorder")
    size = _mcap_size(kill_bag)  # the cycle's states are written; wait for their chunk:
    g.wait_for(lambda: _mcap_size(kill_bag) > size + 1_500_000, 120, "the next chunks")
    before = g.log("hexapod_sim").count("a recorder left the graph")
    assert g.kill("metrics", signal.SIGKILL) == -signal.SIGKILL
    assert part in g.log("metrics") and "bag closed" not in g.log("metrics").split(part)[-1]
    with open_bag(kill_bag) as bag:
        assert bag.truncated
        js = read_joint_state_arrays(bag, T.JOINT_STATES)
    assert len(js.stamps) > 1000 and _contiguous(js.stamps)
    assert g.procs["hexapod_sim"].poll() is None  # the graph went on without its recorder
    # ... and lockstep stopped waiting for it once its peers dropped it (its lease), not
    # after the sim's patience with a silent recorder
    left = "a recorder left the graph"
    g.wait_for(lambda: g.log("hexapod_sim").count(left) >= before + 1, 60,
               "the sim to see the killed recorder leave")
    assert "going on without waiting" not in g.log("hexapod_sim")
