"""R6 in small: every node's resident memory stays flat over a recorded lockstep run (the
soak benchmark, scripts/soak.py, runs the 10 simulated minutes)."""
from __future__ import annotations

import re
import time
from pathlib import Path

from graph.conftest import RECORDED_RUN, finish_recorded_run, start_recorded_run

NODES = ("hexapod_sim",) + RECORDED_RUN
#: Growth allowed per node between a third of the run and its end (MB): R6's bound. The
#: recorder used to keep about twice what it wrote (~2.5 MB per simulated second here, ~70 MB
#: over this span) and far more as the chunks piled up. What may still grow is bounded: the
#: windows of replay protection (msg_auth.REPLAY_WINDOW) fill within the run's first seconds,
#: and the recorder's DDS reader queues (dds_profile: at most 20000 samples each) fill further
#: when a loaded machine lets it fall behind (32 MB seen with a soak run beside the suite).
MAX_GROWTH_MB = 50.0
DURATION = 40.0
#: Growth is measured from the sample after this cycle was scored (10 s simulated).
BASE_CYCLE = 10
CYCLE_LINE = re.compile(r"\]: cycle (\d+) \[")


def test_no_node_grows_over_a_recorded_run(make_graph, tmp_path: Path) -> None:
    """Memory sampled by simulated time (the recorder's cycle lines), not wall time: a
    loaded machine slows the run, and a forked node's pages still being touched (copy on
    write) in its first seconds are not growth."""
    g = make_graph()
    start_recorded_run(g, tmp_path / "bag", DURATION)
    g.wait_log("hexapod_sim", "lockstep mode", timeout=120)
    rss: dict[int, dict[str, float]] = {}  # newest scored cycle -> RSS of every node
    while g.procs["hexapod_sim"].poll() is None:
        done = [int(m) for m in CYCLE_LINE.findall(g.log("metrics"))]
        now = {n: g.rss_mb(n) for n in NODES if g.procs[n].poll() is None}
        if done and len(now) == len(NODES):
            rss.setdefault(max(done), now)
        time.sleep(0.25)
    finish_recorded_run(g, 120)
    first = min((c for c in rss if c >= BASE_CYCLE), default=None)
    last = max(rss, default=None)
    assert first is not None and last is not None and last >= DURATION - 5, sorted(rss)
    growth = {n: rss[last][n] - rss[first][n] for n in NODES}
    assert all(v < MAX_GROWTH_MB for v in growth.values()), (first, last, growth)
