"""Subcommand `montecarlo`: the controllers on uneven ground over many seeds, with intervals.

    hexapod montecarlo --controllers pd_p,pd_pf --seeds 20 --spread 20 --ground 100

Seed k draws every foot's ground factors at every touchdown (log-normal, median 1, sigma =
spread/100 of ln factor) and gives the same ground to every controller (common random
numbers). Printed: each index's mean over the seeds with its 95 % Student t interval, and
each controller's paired difference to the first (paired t on per-seed differences). The
JSON (--json FILE) holds every run with the factors its feet used; ``--seeds 1
--first-seed K`` with the same options replays seed K bit for bit.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Callable

from hexapod_common.core.errors import HexapodError, ParameterError
from hexapod_common.core.params import CONTROLLERS, check_value

from .cli_args import number, params_arguments, params_from_args


def whole(lo: int, hi: int, what: str) -> Callable[[str], int]:
    """An argparse ``type``: a whole number in [lo, hi]."""
    def convert(text: str) -> int:
        try:
            value = int(text.strip())
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"{text!r} is not {what}: a whole number in [{lo}, {hi}]") from None
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(
                f"{text!r} is not {what}: a whole number in [{lo}, {hi}]")
        return value

    convert.__name__ = what
    return convert


def controllers_arg(text: str) -> tuple[str, ...]:
    """``--controllers a,b``: known controllers, each once; HexapodError names the bad one."""
    names = tuple(t.strip() for t in text.split(","))
    for c in names:
        if c not in CONTROLLERS:
            raise HexapodError(f"argument --controllers: {c!r} is not a controller (one of "
                               f"{', '.join(CONTROLLERS)})")
    if len(set(names)) != len(names):
        raise HexapodError(f"argument --controllers: {text!r} names a controller twice")
    return names


def _fmt(iv_mean: float, half: float) -> str:
    if math.isnan(iv_mean):
        return "all diverged"
    if math.isnan(half):
        return f"{iv_mean:.5g} (1 seed)"
    return f"{iv_mean:.5g} ± {half:.2g}"


def _cmd_montecarlo(args: argparse.Namespace) -> int:
    from hexapod_metrics.core.indices import INDEX_UNITS, REPORTED_NAMES

    from .cmd_experiments import _backend, progress_factory
    from .core.montecarlo import monte_carlo

    controllers = controllers_arg(args.controllers)
    if args.ground is not None and args.ground_scale is not None:
        raise HexapodError("give --ground (percent) or --ground-scale (factor), not both")
    p = params_from_args(args)
    if args.ground is not None:
        try:
            scale = check_value("ground.scale", args.ground / 100.0)
        except ParameterError as err:
            raise HexapodError(f"argument --ground: {args.ground:g} %: {err}") from None
        p = p.with_values(**{"ground.scale": scale})
    if args.t_max_run is not None:
        p = p.with_values(**{"run.duration": args.t_max_run})
    seeds = list(range(args.first_seed, args.first_seed + args.seeds))
    show = not args.no_progress and sys.stdout.isatty()
    total = len(seeds) * len(controllers)
    res = monte_carlo(p, controllers, seeds, args.spread / 100.0, backend=_backend(args),
                      progress=progress_factory(show)("monte carlo", total))
    doc = res.as_dict()
    if args.json and args.json != "-":
        Path(args.json).write_text(json.dumps(doc, indent=1, allow_nan=True))
    if args.json == "-":
        print(json.dumps(doc, indent=1, allow_nan=True))
        return 0
    base = controllers[0]
    print(f"Monte Carlo: seeds {seeds[0]}..{seeds[-1]} ({len(seeds)}) x "
          f"{', '.join(controllers)}; ground {100 * p.ground.scale:g} %, spread "
          f"{args.spread:g} % (sigma of ln factor, per foot and touchdown), T_max "
          f"{p.actuator.t_max:g} N m, {res.duration:g} s runs")
    print("95 % intervals: Student t over the seeds; differences: paired t on per-seed "
          "differences (common random numbers); * = interval excludes 0")
    print("diverged: " + ", ".join(f"{c} {res.diverged(c)} of {len(seeds)}"
                                   for c in controllers))
    cols = list(controllers) + [f"{c} - {base}" for c in controllers[1:]]
    print(f"{'index':<8} {'unit':<12}" + "".join(f"{c:>26}" for c in cols))
    for name in REPORTED_NAMES:
        row = f"{name:<8} {INDEX_UNITS[name]:<12}"
        for c in controllers:
            iv = res.interval(c, name)
            row += f"{_fmt(iv.mean, iv.half_width):>26}"
        for c in controllers[1:]:
            d = res.difference(base, c, name)
            row += f"{_fmt(d.mean, d.half_width) + (' *' if d.excludes_zero else '  '):>26}"
        print(row)
    if args.json:
        print(f"every run and its ground factors in {args.json}")
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Register `montecarlo`."""
    from .cmd_experiments import _backend_args

    p = sub.add_parser("montecarlo", help="controllers on uneven ground over N seeds: means, "
                       "95 %% intervals, paired differences")
    params_arguments(p)
    p.add_argument("--controllers", default="pd_p,pd_pf",
                   help=f"comma list of {', '.join(CONTROLLERS)} (the first is the baseline "
                   "of the differences)")
    p.add_argument("--seeds", type=whole(1, 100000, "a seed count"), default=20,
                   help="seeds per controller (default 20)")
    p.add_argument("--first-seed", type=whole(0, 2 ** 53 - 100001, "a seed"), default=0,
                   dest="first_seed", help="seeds FIRST .. FIRST+N-1 (default 0)")
    p.add_argument("--spread", type=number(0.0, 200.0, "a spread in %"), default=20.0,
                   help="sigma of ln(ground factor) in %% (0 = uniform ground; default 20)")
    p.add_argument("--ground", type=number(0.0, 1e6, "a ground percentage", lo_open=True),
                   help="nominal ground in %% of the base values (default: the params file's)")
    p.add_argument("--t-run", type=number(0.0, 1e5, "a duration in s", lo_open=True),
                   dest="t_max_run", metavar="SECONDS",
                   help="simulated seconds per run (default run.duration)")
    p.add_argument("--json", metavar="FILE",
                   help="write every run with its ground factors to FILE ('-': print the "
                   "JSON instead of the table)")
    _backend_args(p)
    p.set_defaults(func=_cmd_montecarlo)


__all__ = ["add_parser", "controllers_arg", "whole"]
