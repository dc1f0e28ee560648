#!/usr/bin/env python3
"""Where a batched step's time goes, and which of its loops over cases run on vectors.

Profile: one block of 64 cases (S2's ground sweep, PD-P and PD-P&F) is run to mid-run with
batch_loop.run_block, then each stage of a tick is timed on that state, calling the
engine's own compiled functions many times: body and legs (block_prepare), the solve
(block_solve), the update (block_integrate), one tick of run_block without scoring and
one with it. Figures are ns per case and physics step (20 kHz physics, 10 kHz control:
a tick is two steps, prepared twice and solved twice), per CPU second of this thread, so
that other load on the machine changes them less than wall time would.

Vectorisation: run_block is compiled again with line tables (numba's debug info with
optimisation and inlining kept as usual) and its machine code counted per loop over
cases (``for b in range(n)`` in batch_physics.py and batch_loop.py): instructions on
512-bit (zmm), 256-bit (ymm) and scalar double registers. A loop that vectorised has
zmm or ymm arithmetic and a scalar remainder; one that did not, scalar only.

Usage: python scripts/profile_batch.py [--reps N] [--no-asm]
"""
from __future__ import annotations

import argparse
import ast
import collections
import os
import re
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np


def _block(ticks: int) -> tuple[Any, dict[str, Any]]:
    """Arguments of run_block for 64 cases of S2's sweep and ``ticks`` ticks."""
    from bench_engine import sweep_cases
    from hexapod_common.core.index_sums import ACC_SIZE
    from hexapod_common.core.layout import model_vector
    from hexapod_common.core.params import load_params
    from hexapod_control.core import closed_loop as cl
    from hexapod_control.core.controllers import gain_vector
    from hexapod_sim.core.batch_physics import LANES
    from hexapod_sim.core.engine import initial_state

    p = load_params()
    cases = sweep_cases(p, 32)
    ref = cl.batch_reference(p, ticks)
    X = np.zeros((initial_state(p).size, LANES))
    PT = np.zeros((model_vector(p).size, LANES))
    G = np.zeros((5, LANES))
    codes = np.zeros(LANES, dtype=np.int64)
    cols = np.zeros(LANES, dtype=np.int64)
    for j, c in enumerate(cases):
        X[:, j], PT[:, j] = initial_state(c.params), model_vector(c.params)
        G[:, j] = gain_vector(c.params.gains(c.controller))
        codes[j], cols[j] = cl.batch_code(c), j
    n = len(cases)
    return p, dict(X=X, PT=PT, codes=codes, G=G, n=n, theta_d=ref.theta[:ticks],
                   theta_vel_d=ref.theta_vel[:ticks], substeps=p.substeps, rec_offset=0,
                   obs_out=np.empty((n, 0, 9, 6, 2)), cols=cols,
                   ok=np.zeros(n, dtype=np.bool_), score_end=-1, hip_ref=ref.hip,
                   foot_ref=ref.foot, acc_out=np.zeros((n, 1, ACC_SIZE)),
                   finite=np.ones(n, dtype=np.bool_))


def _run_block(a: dict[str, Any]) -> None:
    from hexapod_control.core.batch_loop import run_block

    run_block(a["X"], a["PT"], a["codes"], a["G"], a["n"], a["theta_d"], a["theta_vel_d"],
              a["substeps"], a["rec_offset"], a["obs_out"], a["cols"], a["ok"],
              a["score_end"], a["hip_ref"], a["foot_ref"], a["acc_out"], a["finite"])


def profile(reps: int) -> None:
    """Print ns per case-step of each stage (medians of ``reps`` timings)."""
    from numba import njit

    from hexapod_sim.core.batch_physics import (block_integrate, block_prepare,
                                                block_scratch, block_solve)

    @njit
    def stages(X, TQ, PT, n, FH, WK, FF, QDD, TR, FLAG, which, count):  # type: ignore[no-untyped-def]
        for _ in range(count):
            if which == 0:
                block_prepare(X, PT, n, FH, WK, TR)
            elif which == 1:
                block_solve(X, TQ, PT, n, FH, WK, FF, QDD, FLAG)
            else:
                block_integrate(X, PT, n, QDD)

    p, a = _block(15000)  # 1.5 s: walking, feet on and off the ground
    _run_block(a)
    n = a["n"]
    X, PT = a["X"], a["PT"]
    FH, WK, FF, QDD, TR, FLAG = block_scratch()
    TQ = np.zeros((12, X.shape[1]))
    block_prepare(X, PT, n, FH, WK, TR)
    block_solve(X, TQ, PT, n, FH, WK, FF, QDD, FLAG)
    QDD[:] = 0.0  # the update then leaves the state as it is
    count = 2000
    out: dict[str, list[float]] = collections.defaultdict(list)
    for w in range(3):
        stages(X.copy(), TQ, PT, n, FH, WK, FF, QDD, TR, FLAG, w, 10)
    # one tick = substeps physics steps; per tick: substeps prepares and solves
    # (observation shares the first), control law, state check
    for _ in range(reps):
        for w, name in enumerate(("prepare (body, legs)", "solve", "integrate")):
            Xc = X.copy()
            c = time.thread_time()
            stages(Xc, TQ, PT, n, FH, WK, FF, QDD, TR, FLAG, w, count)
            out[name].append((time.thread_time() - c) / (count * n) * 1e9)
        for label, score in (("whole tick, not scoring", False), ("whole tick, scoring", True)):
            b = dict(a, X=X.copy(), PT=PT.copy(), G=a["G"].copy(), codes=a["codes"].copy(),
                     cols=a["cols"].copy(), theta_d=a["theta_d"][:200],
                     theta_vel_d=a["theta_vel_d"][:200])
            if score:
                b["score_end"] = 200
            c = time.thread_time()
            _run_block(b)
            out[label].append((time.thread_time() - c) / (200 * p.substeps * n) * 1e9)
    med = {k: statistics.median(v) for k, v in out.items()}
    s = p.substeps
    print(f"ns per case and physics step ({n} cases, {s} steps a tick; medians of {reps}, "
          f"per CPU s of this thread):")
    for k, per in (("prepare (body, legs)", 1.0), ("solve", (s + 1) / s), ("integrate", 1.0)):
        print(f"  {k:28s} {per * med[k]:7.1f}" + (f"  ({med[k]:.1f} a call; {s + 1} calls a "
                                                  f"tick)" if per != 1.0 else ""))
    whole = med["whole tick, not scoring"]
    # a tick of s steps: s prepares, s + 1 solves (the observation's), s updates
    rest = whole - med["prepare (body, legs)"] - (s + 1) / s * med["solve"] - med["integrate"]
    print(f"  {'control, checks, other':28s} {rest:7.1f}")
    print(f"  {'a step, not scoring':28s} {whole:7.1f}  -> {1e9 / whole / (1 / p.sim.dt):.0f}"
          f" sim s per CPU s")
    print(f"  {'a step, scoring every tick':28s} {med['whole tick, scoring']:7.1f}")


def _loops() -> list[tuple[str, str, int, int]]:
    """(file, function, first line, last line) of every loop over cases b."""
    import hexapod_control.core.batch_loop as bl
    import hexapod_sim.core.batch_physics as bp

    found = []
    for mod in (bp, bl):
        path = Path(mod.__file__ or "")
        tree = ast.parse(path.read_text())
        for fn in tree.body:
            if not isinstance(fn, ast.FunctionDef):
                continue
            for node in ast.walk(fn):
                if (isinstance(node, ast.For) and isinstance(node.target, ast.Name)
                        and node.target.id == "b"):
                    found.append((path.name, fn.name, node.lineno, node.end_lineno or 0))
    return found


def _with_line_tables() -> None:
    """numba's debug line tables without its debug mode's other changes (no inlining,
    bounds checks, longer lifetimes), so that the machine code is the usual one."""
    from numba.core import cpu, lowering

    finalize = cpu.CPUTargetOptions.finalize
    pre_lower = lowering.Lower.pre_lower

    def _finalize(self: Any, flags: Any, options: Any) -> None:
        finalize(self, flags, options)
        flags.debuginfo = True
        flags.boundscheck = False
        flags.dbg_extend_lifetimes = False

    def _pre_lower(self: Any) -> None:
        pre_lower(self)
        self.builder.function.attributes.discard("noinline")

    cpu.CPUTargetOptions.finalize = _finalize
    lowering.Lower.pre_lower = _pre_lower


def vector_report() -> None:
    """Print, per loop over cases, its instructions on zmm, ymm and scalar registers."""
    from hexapod_control.core import batch_loop

    _, a = _block(4)
    _run_block(a)
    asm = batch_loop.run_block.inspect_asm(batch_loop.run_block.signatures[0])
    files = {m.group(1): Path(m.group(3) or m.group(2)).name for m in re.finditer(
        r'\.file\s+(\d+)\s+"([^"]*)"(?:\s+"([^"]*)")?', asm)}
    per_line: dict[tuple[str, int], collections.Counter[str]] = collections.defaultdict(
        collections.Counter)
    here: tuple[str, int] | None = None
    for line in asm.splitlines():
        s = line.strip()
        m = re.match(r"\.loc\s+(\d+)\s+(\d+)", s)
        if m:
            here = (files.get(m.group(1), "?"), int(m.group(2)))
            continue
        if here is None or not s or s[0] in ".#" or s.endswith(":"):
            continue
        op = s.split()[0]
        kind = ("zmm" if "zmm" in s else "ymm" if "ymm" in s
                else "scalar" if re.match(r"v\w+sd$", op) else "other")
        per_line[here][kind] += 1
    print("\nloops over cases in run_block's machine code (instructions by register):")
    print(f"  {'loop':40s} {'zmm':>5s} {'ymm':>5s} {'scalar':>6s}  vectorised")
    for f, fn, lo, hi in _loops():
        c: collections.Counter[str] = collections.Counter()
        for (ff, ln), k in per_line.items():
            if ff == f and lo <= ln <= hi:
                c.update(k)
        if not sum(c.values()):
            continue
        vec = "yes" if c["zmm"] + c["ymm"] else "no"
        print(f"  {f + ':' + str(lo) + ' ' + fn:40s} {c['zmm']:5d} {c['ymm']:5d} "
              f"{c['scalar']:6d}  {vec}")
    print("  (inlined helpers' lines count under their own files; sincos, dynamics: "
          + ", ".join(f"{f} zmm {sum(v['zmm'] for (ff, _), v in per_line.items() if ff == f)}"
                      f" scalar {sum(v['scalar'] for (ff, _), v in per_line.items() if ff == f)}"
                      for f in ("sincos.py", "dynamics.py")) + ")")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--reps", type=int, default=5, help="timings per stage (median)")
    ap.add_argument("--no-asm", action="store_true", help="skip the vectorisation report")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    if not args.no_asm:
        # a fresh cache: the line tables need a compile, and must not go to the real cache
        os.environ["NUMBA_CACHE_DIR"] = tempfile.mkdtemp(prefix="profile_batch_")
        _with_line_tables()
    import hexapod_common.core  # noqa: F401  (512-bit vectors before anything compiles)
    from numba.core import config

    from hexapod_common.core.vector_width import force_avx2_width

    wide = (config.CPU_FEATURES or "").endswith("-prefer-256-bit")
    print("vectors: " + ("512-bit preferred" if wide else
                         "4 doubles forced (AVX2 host)" if force_avx2_width() else
                         "LLVM's own choice"))
    profile(args.reps)
    if not args.no_asm:
        vector_report()
    return 0


if __name__ == "__main__":
    sys.exit(main())
