#!/usr/bin/env python3
"""Benchmark R: `hexapod reproduce` on the local process pool against a local Dask cluster.

Runs ``hexapod reproduce`` (``--quick`` unless ``--full``) alternately with ``--backend
processes`` (one worker process per core) and ``--dask local:N`` (a local Dask cluster of N
single-threaded workers), ``--reps`` times each, every run niced (``--nice``, the machine is
shared), and prints each run's wall time, the CPU seconds of the command and its workers,
the load average around it, and the medians; it also checks that both backends wrote the
same claims and numbers (results.json).

With ``--vs-batched`` it instead runs the reproduction in this process on the local process
pool, records every batched case it runs (the experiments' points, each once) and its
single runs (whole time series for the figures and torque numbers, uneven-ground Monte
Carlo runs), then times the single runs again on the same workers and the batched engine on
those same cases in one batch per shared reference and duration (numba's threads on every
core): the reproduction's wall time against the engine's on the same simulation work
(target: the engine's time >= 0.8 of the reproduction's).

Usage: python scripts/bench_reproduce.py [--reps 2] [--workers 2] [--nice 10] [--full]
       [--vs-batched]
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import host_speed

TARGET_S = {"quick": 120.0, "full": 600.0}


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def run_once(backend: list[str], out: Path, quick: bool, nice: int) -> dict[str, float]:
    """One `hexapod reproduce`; wall s, CPU s (command and workers), load before/after."""
    cmd = ["nice", "-n", str(nice), sys.executable, "-m", "hexapod_bringup.cli", "reproduce",
           *(["--quick"] if quick else []), *backend, "--no-progress", "--out", str(out)]
    load0, cpu0, t0 = os.getloadavg()[0], _children_cpu(), time.perf_counter()
    r = subprocess.run(cmd, check=False, capture_output=True, text=True)
    wall, cpu = time.perf_counter() - t0, _children_cpu() - cpu0
    if r.returncode:
        raise RuntimeError(f"{' '.join(cmd)} exited {r.returncode}: {r.stderr.strip()[-400:]}")
    return {"wall": wall, "cpu": cpu, "load0": load0, "load1": os.getloadavg()[0]}


class _Recording:
    """A backend that runs on ``inner`` and records the batched cases and single runs."""

    def __init__(self, inner: object) -> None:
        self.inner = inner
        self.cases: list[tuple[object, float]] = []
        self.singles: list[tuple[object, list[object]]] = []

    @property
    def workers(self) -> int:
        return int(self.inner.workers)  # type: ignore[attr-defined]

    def map(self, chunks):  # type: ignore[no-untyped-def]
        for _, cases, duration in chunks:
            self.cases += [(c, duration) for c in cases]
        return self.inner.map(chunks)  # type: ignore[attr-defined]

    def calls(self, fn, items):  # type: ignore[no-untyped-def]
        self.singles.append((fn, list(items)))
        return self.inner.calls(fn, items)  # type: ignore[attr-defined]


def vs_batched(quick: bool, workers: int) -> int:
    """The reproduction in process against the batched engine on its batched cases."""
    from hexapod_bringup.core.parallel import ProcessBackend
    from hexapod_bringup.core.simulate import evaluate_batch
    from hexapod_bringup.report import Plan, reproduce
    from hexapod_common.core.params import load_params
    from hexapod_control.core.closed_loop import shared_reference_key

    p = load_params()
    with ProcessBackend(workers) as pool, tempfile.TemporaryDirectory() as tmp:
        rec = _Recording(pool.start())
        t0 = time.perf_counter()
        reproduce(p, Path(tmp), rec, Plan.quick() if quick else Plan())  # type: ignore[arg-type]
        t_rep = time.perf_counter() - t0
        t0 = time.perf_counter()  # the single runs again, on the same workers
        for fn, items in rec.singles:
            for _ in pool.calls(fn, items):  # type: ignore[arg-type]
                pass
        t_single = time.perf_counter() - t0
    groups: dict[tuple[object, ...], list[object]] = {}
    for case, duration in rec.cases:
        groups.setdefault((shared_reference_key(case.params), duration), []).append(case)  # type: ignore[attr-defined]
    sim = sum(d * len(cs) for (_, d), cs in groups.items())
    for (_, d), cs in groups.items():  # warm-up: load the compiled code
        evaluate_batch(cs[:1], d)
        break
    t0 = time.perf_counter()
    for (_, d), cs in groups.items():
        evaluate_batch(cs, d)  # type: ignore[arg-type]
    t_batch = time.perf_counter() - t0
    n_single = sum(len(items) for _, items in rec.singles)
    print(f"reproduce {'--quick' if quick else '(full)'} in process on {workers} workers: "
          f"{t_rep:.1f} s wall; {len(rec.cases)} batched runs ({sim:g} sim s, "
          f"{len(groups)} batches) and {n_single} single runs")
    print(f"the engine on the same work: {t_batch:.1f} s for the batched runs in one batch each "
          f"({sim / t_batch:.0f} sim s/s) + {t_single:.1f} s for the single runs on the "
          f"workers = {t_batch + t_single:.1f} s")
    print(f"ratio (engine time / reproduction time): {(t_batch + t_single) / t_rep:.2f} "
          f"(batched runs alone: {t_batch / t_rep:.2f}); target 0.8")
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=2)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--nice", type=int, default=10)
    ap.add_argument("--full", action="store_true", help="the whole reproduction, not --quick")
    ap.add_argument("--vs-batched", action="store_true",
                    help="the reproduction against the batched engine on its batched runs")
    args = ap.parse_args(argv)
    if args.vs_batched:
        return vs_batched(not args.full, args.workers)
    kind = "full" if args.full else "quick"
    backends = {"processes": ["--backend", "processes"],
                f"dask local:{args.workers}": ["--dask", f"local:{args.workers}"]}
    print(f"machine: {os.cpu_count()} cores, {host_speed.describe()}, "
          f"load average {os.getloadavg()[0]:.2f}; "
          f"reproduce {'--quick' if kind == 'quick' else '(full)'}, nice {args.nice}",
          flush=True)
    rows: dict[str, list[dict[str, float]]] = {k: [] for k in backends}
    results: dict[str, object] = {}
    with tempfile.TemporaryDirectory(prefix="bench_reproduce_") as tmp:
        for i in range(args.reps):
            for name, opts in backends.items():
                out = Path(tmp) / f"{name.replace(' ', '_').replace(':', '')}_{i}"
                r = run_once(opts, out, kind == "quick", args.nice)
                rows[name].append(r)
                doc = json.loads((out / "results.json").read_text())
                results.setdefault(name, doc)
                print(f"{name} run {i + 1}: wall {r['wall']:.1f} s, CPU {r['cpu']:.1f} s "
                      f"(command + workers), load average {r['load0']:.1f} -> "
                      f"{r['load1']:.1f}", flush=True)
    docs = list(results.values())
    same = all(json.dumps(d, sort_keys=True) == json.dumps(docs[0], sort_keys=True)
               for d in docs)
    print(f"results.json identical across backends: {'yes' if same else 'NO'}")
    for name, rs in rows.items():
        wall = statistics.median(r["wall"] for r in rs)
        cpu = statistics.median(r["cpu"] for r in rs)
        print(f"R reproduce {kind} on {name}: median wall {wall:.1f} s, CPU {cpu:.1f} s over "
              f"{len(rs)} runs (target < {TARGET_S[kind]:g} s; gap {wall / TARGET_S[kind]:.2f})")
    print(f"load average after: {os.getloadavg()[0]:.2f}; {host_speed.describe()}")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
