#!/usr/bin/env python3
"""A user's sweep against the batched engine on the same work, side by side, alternating.

Per round:
  batched  one process runs the sweep's cases in one batch, scored on the fly as the sweep
           does (``closed_loop.score_batch``, numba's threads on every core), then S2's own
           case set (25-200 % ground, 2 x 64 cases) as S2 measures it (scored) and recording
           the last cycle (``run_batch``); all timed by bench_engine.py's S2 code
           (bench_batch);
  sweep    ``hexapod sweep ground --range R --t-max-list T`` (the user's command: progress
           off, its CSV, JSON and seven figures written), wall time;
  start    ``hexapod sweep --help`` (interpreter and command-line start-up), subtracted.
The figure of merit is the sweep's overhead beyond the batched runs, in seconds: its wall time
less the same cases' time in one batch (target <= 1.5 s, issue 37: seconds, not a ratio that
shrinks as the engine gets faster); the sweep's rate, its simulated seconds over (wall -
start-up), over the batched engine's is printed too. Medians of --runs rounds.

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
from pathlib import Path
from typing import Callable

import host_speed
from project_env import reexec_in_env

BATCHED = r"""
import json, sys
sys.path.insert(0, sys.argv[3])
from bench_engine import bench_batch, bench_s2
from bench_engine import sweep_cases as sweep_cases_s2
from hexapod_bringup.cli_args import parse_range
from hexapod_bringup.core.experiments import sweep_cases
from hexapod_common.core.params import load_params
rng, t_max = sys.argv[1], float(sys.argv[2])
p = load_params(None)
d = p.run.duration
user = sweep_cases(p.with_values(**{"actuator.t_max": t_max}), "ground.scale",
                   [v / 100 for v in parse_range(rng)], ("pd_p", "pd_pf"))
print(json.dumps({"duration": d, "cases": len(user),
                  "user": bench_batch(user, d, 1, score=True)["rates"][0],
                  "s2": bench_s2(p, 64, d, 1, False)["rates"][0],
                  "s2_recording": bench_batch(sweep_cases_s2(p, 64), d, 1)["rates"][0]}))
"""


class StepFailed(Exception):
    """A command of the benchmark failed: its name, exit code and last line of stderr."""


def step(what: str, cmd: list[str]) -> tuple[float, str]:
    """Wall seconds and stdout of command ``cmd`` (StepFailed names ``what``)."""
    t = time.perf_counter()
    res = subprocess.run(cmd, capture_output=True, text=True)
    if res.returncode != 0:
        tail = res.stderr.strip().splitlines()[-1:] or ["no message"]
        raise StepFailed(f"{what} failed (exit {res.returncode}): {tail[0]}")
    return time.perf_counter() - t, res.stdout


def main() -> int:
    reexec_in_env(__file__)
    from hexapod_bringup.cli_args import number, value_range

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=rounds, default=3, help="rounds (medians are quoted)")
    ap.add_argument("--range", type=checked(value_range), default="10:1000:128",
                    help="the sweep's --range (ground in %%)")
    ap.add_argument("--t-max-list", type=checked(number(0.0, lo_open=True, what="T_max")),
                    default="400", help="the sweep's --t-max-list (one value, N m)")
    args = ap.parse_args()
    try:
        return bench(args)
    except StepFailed as err:
        print(f"bench_sweep: {err}", file=sys.stderr)
        return 1


def rounds(text: str) -> int:
    """argparse type: a whole number of rounds >= 1."""
    if not text.isdigit() or int(text) < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, got {text!r}")
    return int(text)


def checked(convert: Callable[[str], object]) -> Callable[[str], str]:
    """argparse type: ``text`` unchanged once ``convert`` (which raises) accepts it."""
    def check(text: str) -> str:
        convert(text)
        return text
    return check


def bench(args: argparse.Namespace) -> int:
    """The rounds and the summary."""
    cli = [sys.executable, "-m", "hexapod_bringup.cli"]
    rows: dict[str, list[float]] = {"user": [], "s2": [], "s2_recording": [], "sweep": [],
                                    "start": []}
    info: dict[str, float] = {}
    print(host_speed.describe(), flush=True)
    with tempfile.TemporaryDirectory() as out:
        for r in range(args.runs):
            _, out_text = step("the batched engine's run", [
                sys.executable, "-c", BATCHED, args.range, args.t_max_list,
                str(Path(__file__).resolve().parent)])
            info = json.loads(out_text.strip().splitlines()[-1])
            rows["user"].append(info["user"])
            rows["s2"].append(info["s2"])
            rows["s2_recording"].append(info["s2_recording"])
            rows["sweep"].append(step("hexapod sweep", cli + [
                "sweep", "ground", "--range", args.range, "--t-max-list", args.t_max_list,
                "--no-progress", "--out", out])[0])
            rows["start"].append(step("hexapod sweep --help", cli + ["sweep", "--help"])[0])
            print(f"round {r + 1}: batched {info['user']:.0f} sim s/s (S2's cases "
                  f"{info['s2']:.0f}), sweep {rows['sweep'][-1]:.2f} s, start-up "
                  f"{rows['start'][-1]:.2f} s", flush=True)
    sim = info["cases"] * info["duration"]
    med = {k: statistics.median(v) for k, v in rows.items()}
    rate = sim / (med["sweep"] - med["start"])
    print(f"\nmedians of {args.runs}: {info['cases']} runs x {info['duration']:g} s = "
          f"{sim:g} sim s")
    print(f"  batched engine, same cases, one batch, scored: {med['user']:.0f} sim s/s")
    print(f"  batched engine, S2's cases (S2):               {med['s2']:.0f} sim s/s")
    print(f"  batched engine, S2's cases, recording:         {med['s2_recording']:.0f} sim s/s")
    print(f"  user's sweep: {med['sweep']:.2f} s wall - {med['start']:.2f} s start-up = "
          f"{rate:.0f} sim s/s")
    over = med["sweep"] - sim / med["user"]
    print(f"  overhead beyond the batched runs: {med['sweep']:.2f} s - {sim / med['user']:.2f} s "
          f"(the same cases in one batch) = {over:.2f} s (target <= 1.5 s: start-up, "
          f"figures, files)")
    print(f"  ratio to S2's rate: {rate / med['s2']:.2f}; to the same cases in one "
          f"batch: {rate / med['user']:.2f}; to S2's cases recorded: "
          f"{rate / med['s2_recording']:.2f}")
    print(host_speed.describe())
    return 0


if __name__ == "__main__":
    sys.exit(main())
