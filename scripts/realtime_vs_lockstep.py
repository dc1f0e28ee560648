#!/usr/bin/env python3
"""The indices of a realtime graph run next to a lockstep run of the same scenario.

Both runs: ``scripts/run_graph.sh --no-switch`` with one controller, the realtime default's
rate and placement (1 kHz, PD-P&F's force loop in the drive) unless ``--set`` says
otherwise. Prints each full gait cycle's indices of both runs, their difference, and the
realtime run's late and missed ticks and uncommanded (held) ticks per cycle: in lockstep
every tick's command is the one computed from that tick's state; in realtime a command that
misses its period is replaced by the previous torque (held), which is where the two runs
part. Exit status 0 if both runs exited 0.

    scripts/realtime_vs_lockstep.py --duration 6 [--controller pd_pf] [--set NAME=VALUE]
"""
from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: Indices whose difference is said in % (the others are lengths, said in mm).
RELATIVE = ("E_av", "T_L", "F_L")


def run(mode: str, a: argparse.Namespace, out: Path) -> tuple[int, dict, str]:
    """(exit code, indices.json, the sim's summary line) of one run."""
    bag = out / mode
    args = [str(ROOT / "scripts" / "run_graph.sh"), "--mode", mode, "--no-switch",
            "--controller", a.controller, "--duration", str(a.duration),
            "--control-rate", "1000", "--set", "pd_pf.force_loop=drive", "--bag", str(bag)]
    for s in a.set:
        args += ["--set", s]
    proc = subprocess.run(args, capture_output=True, text=True)
    try:
        doc = json.loads((bag / "indices.json").read_text())
    except (OSError, ValueError):
        said = (proc.stderr.strip().splitlines() or ["(nothing on stderr)"])[-1]
        sys.exit(f"realtime_vs_lockstep: the {mode} run left no indices.json "
                 f"(exit {proc.returncode}): {said}")
    log = Path(f"{bag}_logs/hexapod_sim.log").read_text(errors="replace")
    m = re.search(r"stopped at tick .*", log)
    return proc.returncode, doc, m[0] if m else "(no summary line)"


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--duration", type=float, default=6.0, help="simulated s (default 6)")
    p.add_argument("--controller", default="pd_pf", choices=("pd_p", "pd_pf"))
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="a parameter for both runs (repeatable)")
    a = p.parse_args()
    with tempfile.TemporaryDirectory(prefix="rt_vs_ls_") as tmp:
        codes, docs = {}, {}
        for mode in ("lockstep", "realtime"):
            codes[mode], docs[mode], line = run(mode, a, Path(tmp))
            print(f"{mode}: exit {codes[mode]}; sim {line.split(' in ', 1)[-1][:220]}")
    names = docs["lockstep"]["index_names"]
    cycles = {m: {c["cycle"]: c for c in d["cycles"]} for m, d in docs.items()}
    common = sorted(cycles["lockstep"].keys() & cycles["realtime"].keys())
    print(f"\n{'cycle':<6}{'run':<10}{'held':>6}" + "".join(f"{n:>13}" for n in names))
    worst = {n: 0.0 for n in names}
    for k in common:
        ls, rt = cycles["lockstep"][k], cycles["realtime"][k]
        for label, c in (("lockstep", ls), ("realtime", rt)):
            print(f"{k:<6}{label:<10}{c['uncommanded_ticks']:>6}"
                  + "".join(f"{c['indices'][n]:>13.5g}" for n in names))
        diffs = []
        for n in names:
            x, y = ls["indices"][n], rt["indices"][n]
            d = (100 * (y - x) / x if x else float("nan")) if n in RELATIVE else 1e3 * (y - x)
            if k > 0:  # cycle 0 starts from rest in both runs; the steady gait from 1 on
                worst[n] = max(worst[n], abs(d))
            diffs.append(f"{d:+.3g}{' %' if n in RELATIVE else ' mm'}".rjust(13))
        print(f"{k:<6}{'diff':<10}{'':>6}" + "".join(diffs))
    print("\nlargest |difference| over cycles 1-: " + ", ".join(
        f"{n} {worst[n]:.3g} {'%' if n in RELATIVE else 'mm'}" for n in names))
    return 0 if all(c == 0 for c in codes.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
