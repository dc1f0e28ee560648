#!/usr/bin/env python3
"""What the node fork server buys: a graph's start-up with nodes forked from the launcher's
pre-imported fork server (hexapod_common/runtime/node_fork.py, the default) against nodes
started as new interpreters (``GraphProcesses(fork=False)``), side by side, alternating.

Each run starts the five nodes of a lockstep graph (recorder, generator, both controllers,
the sim) on its own ROS_DOMAIN_ID and measures, once the sim has published tick 0: the wall
seconds from the first start to tick 0 and the CPU seconds the five node processes used so
far. The fork server's own start (its imports and numba kernels, once per launcher process)
is printed apart. Medians of --runs per way.

Usage: scripts/bench_startup.py [--runs 5]
(run through `scripts/env.sh`, or it re-executes itself inside it).
"""
from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

from project_env import reexec_in_env

NODES = ("metrics", "trajectory_generator", "pd_p_controller", "pd_pf_controller",
         "hexapod_sim")


def start_graph(fork: bool, domain: int, log_dir: Path) -> tuple[float, float]:
    """Wall s to tick 0 and the nodes' CPU s by then, for one graph."""
    from hexapod_bringup.cmd_graph import GraphProcesses

    g = GraphProcesses(log_dir, env={"ROS_DOMAIN_ID": str(domain)}, fork=fork)
    try:
        t0 = time.monotonic()
        g.start("metrics", f"bag_path:={log_dir / 'bag'}")
        for name in NODES[1:-1]:
            g.start(name)
        g.start("hexapod_sim", "run.duration:=60")
        g.wait_log("hexapod_sim", "lockstep mode", timeout=120)
        wall = time.monotonic() - t0
        cpu = sum(g.cpu_seconds(n) for n in NODES)
    finally:
        g.stop_all(order=NODES)
    return wall, cpu


def server_cpu() -> float:
    """CPU s the fork server of this process has used (NaN if none runs)."""
    import multiprocessing.forkserver as fs

    pid = fs._forkserver._forkserver_pid  # type: ignore[attr-defined]
    if pid is None:
        return float("nan")
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def main() -> int:
    reexec_in_env(__file__)
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=5)
    args = ap.parse_args()
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.2f}")
    rows: dict[bool, list[tuple[float, float]]] = {True: [], False: []}
    base = 150 + os.getpid() % 80
    with tempfile.TemporaryDirectory(prefix="bench_startup_") as tmp:
        for i in range(args.runs):
            for fork in ((True, False) if i % 2 == 0 else (False, True)):
                wall, cpu = start_graph(fork, base + len(rows[True]) + len(rows[False]),
                                        Path(tmp) / f"{'fork' if fork else 'exec'}_{i}")
                rows[fork].append((wall, cpu))
                print(f"run {i + 1} {'forked' if fork else 'new interpreters'}: tick 0 "
                      f"after {wall:.2f} s, nodes' CPU {cpu:.2f} s", flush=True)
    for fork in (True, False):
        walls, cpus = zip(*rows[fork])
        print(f"{'forked' if fork else 'new interpreters'}: median tick 0 after "
              f"{statistics.median(walls):.2f} s, nodes' CPU {statistics.median(cpus):.2f} s")
    print(f"fork server (once per launcher process): {server_cpu():.2f} CPU s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
