#!/usr/bin/env python3
"""Start-up times: of a graph's nodes, and of the command line against a running graph.

Default: what the node fork server buys: a graph's start-up with nodes forked from the
launcher's pre-imported fork server (hexapod_common/runtime/node_fork.py, the default)
against nodes started as new interpreters (``GraphProcesses(fork=False)``), side by side,
alternating. Each run starts the five nodes of a lockstep graph (recorder, generator, both
controllers, the sim) on its own ROS_DOMAIN_ID and measures, once the sim has published tick
0: the wall seconds from the first start to tick 0 and the CPU seconds the five node
processes used so far. The fork server's own start (its imports and numba kernels, once per
launcher process) is printed apart. Medians of --runs per way.

``--cli N`` (the CLI row of docs/benchmarks.md): wall seconds of ``scripts/hexapod status``
and ``scripts/hexapod switch`` (pd_p and pd_pf in turn) as a user types them in a shell that
has not sourced scripts/env.sh, N of each, on a running lockstep graph (the default
scenario, unpaced: it keeps both cores busy), then N of each on a domain where nothing runs;
medians, with the fastest and slowest.

Usage: scripts/bench_startup.py [--runs 5] [--cli N]
(run through `scripts/env.sh`, or it re-executes itself inside it).
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

from host_speed import describe
from project_env import ROOT, reexec_in_env

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


#: What a shell that has not sourced scripts/env.sh lacks of it.
ENV_SH = ("VIRTUAL_ENV", "PYTHONPATH", "LD_LIBRARY_PATH", "AMENT_PREFIX_PATH",
          "COLCON_PREFIX_PATH", "_ROS_WHEELS_BOOTSTRAP_COMPLETE", "NUMBA_CACHE_DIR")


def time_cli(domain: int, *args: str) -> tuple[float, int, str]:
    """Wall s of one ``scripts/hexapod ARGS`` from a plain shell; its exit code and output."""
    env = {k: v for k, v in os.environ.items() if k not in ENV_SH}
    env["ROS_DOMAIN_ID"] = str(domain)
    t = time.monotonic()
    r = subprocess.run([str(ROOT / "scripts" / "hexapod"), *args], env=env,
                       capture_output=True, text=True)
    return time.monotonic() - t, r.returncode, (r.stdout + r.stderr).strip()


def _line(what: str, times: list[float]) -> str:
    return (f"{what}: median {statistics.median(times):.2f} s (fastest {min(times):.2f}, "
            f"slowest {max(times):.2f}, {len(times)} runs)")


def cli_bench(n: int, tmp: Path) -> None:
    """The CLI's answers on a running graph and on an empty domain (module doc)."""
    from hexapod_bringup.cmd_graph import GraphProcesses

    domain = 150 + os.getpid() % 80
    g = GraphProcesses(tmp / "cli", env={"ROS_DOMAIN_ID": str(domain)})
    times: dict[str, list[float]] = {"status": [], "switch": []}
    try:
        g.start("metrics", f"bag_path:={tmp / 'cli' / 'bag'}")
        for name in NODES[1:-1]:
            g.start(name)
        g.start("hexapod_sim", "run.duration:=100000", f"wait_for:={','.join(NODES[:-1])}")
        g.wait_log("hexapod_sim", "lockstep mode", timeout=120)
        for i in range(n):
            for args in (("status",), ("switch", "pd_p" if i % 2 == 0 else "pd_pf")):
                wall, code, out = time_cli(domain, *args)
                if code != 0:
                    raise SystemExit(f"bench_startup.py: `hexapod {' '.join(args)}` failed: "
                                     f"{out}")
                times[args[0]].append(wall)
        print(_line("running graph, `scripts/hexapod status`", times["status"]))
        print(_line("running graph, `scripts/hexapod switch`", times["switch"]))
    finally:
        g.stop_all(order=NODES[::-1])
    empty = domain + 1
    for what in (("status",), ("switch", "pd_p")):
        walls = []
        for _ in range(n):
            wall, code, out = time_cli(empty, *what)
            if code == 0 or "nothing runs" not in out:
                raise SystemExit(f"bench_startup.py: expected an error, got {code}: {out}")
            walls.append(wall)
        print(_line(f"no graph, `scripts/hexapod {what[0]}` to its error", walls))


def main() -> int:
    reexec_in_env(__file__)
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--cli", type=int, default=0, metavar="N",
                    help="time the command line instead (N calls of each)")
    args = ap.parse_args()
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.2f}")
    if args.cli:
        print(describe(), flush=True)
        with tempfile.TemporaryDirectory(prefix="bench_startup_") as tmp:
            cli_bench(args.cli, Path(tmp))
        print(describe(), f"; load average {os.getloadavg()[0]:.2f}")
        return 0
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
