#!/usr/bin/env python3
"""A user's sweep against the batched engine on the same work, side by side, alternating.

Per round:
  batched  one process runs ``closed_loop.run_batch`` on the sweep's cases in one batch
           (numba's threads on every core; a warm-up batch first, as S2 does), and on S2's
           own case set (bench_engine.py: 25-200 % ground, 2 x 64 cases);
  sweep    ``hexapod sweep ground --range R --t-max-list T`` (the user's command: progress
           off, its CSV, JSON and seven figures written), wall time;
  start    ``hexapod sweep --help`` (interpreter and command-line start-up), subtracted.
The sweep's rate is its simulated seconds over (wall - start-up); the figure of merit is that
rate over the batched engine's on the same cases (target >= 0.8, quality.md). Medians of
--runs rounds.

Usage: scripts/bench_sweep.py [--runs 3] [--range 10:1000:128] [--t-max-list 400]
(run through `scripts/env.sh`, or it re-executes itself inside it).
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time

from project_env import reexec_in_env

BATCHED = r"""
import json, sys, time
import numpy as np
from hexapod_bringup.cli_args import parse_range
from hexapod_bringup.core.simulate import window_ticks
from hexapod_common.core.params import load_params
from hexapod_control.core.closed_loop import Case, run_batch
rng, t_max, controllers = sys.argv[1], float(sys.argv[2]), ("pd_p", "pd_pf")
p = load_params(None).with_values(**{"actuator.t_max": t_max})
d = p.run.duration
k_a, _ = window_ticks(p, d)
rec = k_a * p.sim.control_period
user = [Case(p.with_values(**{"ground.scale": v / 100}), c)
        for c in controllers for v in parse_range(rng)]
s2 = [Case(load_params(None).with_values(**{"ground.scale": float(s)}), c)
      for c in controllers for s in np.linspace(0.25, 2.0, 64)]
run_batch(user[:2], 10 * p.sim.control_period, 0.0)  # warm-up: load the kernels
out = {"duration": d, "cases": len(user)}
for name, cases in (("user", user), ("s2", s2)):
    t = time.perf_counter()
    run_batch(cases, d, rec)
    out[name] = len(cases) * d / (time.perf_counter() - t)
print(json.dumps(out))
"""


def timed(cmd: list[str]) -> float:
    """Wall seconds of a command (its output discarded; a failure stops the benchmark)."""
    t = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - t


def main() -> int:
    reexec_in_env(__file__)
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=3, help="rounds (medians are quoted)")
    ap.add_argument("--range", default="10:1000:128", help="the sweep's --range")
    ap.add_argument("--t-max-list", default="400", help="the sweep's --t-max-list (one value)")
    args = ap.parse_args()
    cli = [sys.executable, "-m", "hexapod_bringup.cli"]
    rows: dict[str, list[float]] = {"user": [], "s2": [], "sweep": [], "start": []}
    info: dict[str, float] = {}
    with tempfile.TemporaryDirectory() as out:
        for r in range(args.runs):
            res = subprocess.run([sys.executable, "-c", BATCHED, args.range, args.t_max_list],
                                 check=True, capture_output=True, text=True)
            info = json.loads(res.stdout.strip().splitlines()[-1])
            rows["user"].append(info["user"])
            rows["s2"].append(info["s2"])
            rows["sweep"].append(timed(cli + ["sweep", "ground", "--range", args.range,
                                              "--t-max-list", args.t_max_list,
                                              "--no-progress", "--out", out]))
            rows["start"].append(timed(cli + ["sweep", "--help"]))
            print(f"round {r + 1}: batched {info['user']:.0f} sim s/s (S2's cases "
                  f"{info['s2']:.0f}), sweep {rows['sweep'][-1]:.2f} s, start-up "
                  f"{rows['start'][-1]:.2f} s", flush=True)
    sim = info["cases"] * info["duration"]
    med = {k: statistics.median(v) for k, v in rows.items()}
    rate = sim / (med["sweep"] - med["start"])
    print(f"\nmedians of {args.runs}: {info['cases']} runs x {info['duration']:g} s = "
          f"{sim:g} sim s")
    print(f"  batched engine, same cases, one batch:   {med['user']:.0f} sim s/s")
    print(f"  batched engine, S2's cases:              {med['s2']:.0f} sim s/s")
    print(f"  user's sweep: {med['sweep']:.2f} s wall - {med['start']:.2f} s start-up = "
          f"{rate:.0f} sim s/s")
    print(f"  ratio to the batched engine, same cases: {rate / med['user']:.2f} "
          f"(S2's cases: {rate / med['s2']:.2f}); target 0.8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
