"""Subcommand `montecarlo`: the controllers on uneven ground over many seeds, with intervals.

    hexapod montecarlo --controllers pd_p,pd_pf --seeds 20 --spread 20 --ground 100

    hexapod montecarlo --seeds 20 --ground 50,100,500 --spread 0,20,50 --t-max-list 400,170

Seed k draws every foot's ground factors at every touchdown (log-normal, median 1, sigma =
spread/100 of ln factor) and gives the same ground to every controller (common random
numbers). Printed: each index's mean over the seeds with its 95 % Student t interval, and
each controller's paired difference to the first (paired t on per-seed differences). The
JSON (--json FILE) holds every run with the factors its feet used; ``--seeds 1
--first-seed K`` with the same options replays seed K bit for bit. With several grounds,
spreads or T_max values (E8) it prints per point who has the lower hip errors
(trk_xH + eps_yH) by the paired interval, and how many seeds that took or would take.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Callable

from hexapod_common.core.errors import HexapodError, ParameterError
from hexapod_common.core.params import CONTROLLERS, check_value

from .cli_args import number, params_arguments, params_from_args, read_number

if TYPE_CHECKING:
    from hexapod_common.core.params import HexapodParams

    from .core.montecarlo import MonteCarloResult


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


def number_list(lo: float, hi: float, what: str, lo_open: bool = False
                ) -> Callable[[str], list[float]]:
    """An argparse ``type``: a comma list of numbers, each in [lo, hi] ((lo, hi] if
    ``lo_open``; ``hi`` may be inf)."""
    def convert(text: str) -> list[float]:
        out = []
        for item in text.split(","):
            try:
                v = read_number(item.strip())
            except ValueError:
                v = math.nan
            ok = (not math.isnan(v) and lo <= v <= hi and not (lo_open and v == lo)
                  and (math.isfinite(v) or hi == math.inf))
            if not ok:
                left = "(" if lo_open else "["
                raise argparse.ArgumentTypeError(
                    f"{item.strip()!r} is not {what} in {left}{lo:g}, {hi:g}]")
            out.append(v)
        return out

    convert.__name__ = what
    return convert


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
    if args.t_max_list is not None and args.t_max is not None:
        raise HexapodError("give --t-max or --t-max-list, not both")
    p = params_from_args(args)
    for g in args.ground or []:
        try:
            check_value("ground.scale", g / 100.0)
        except ParameterError as err:
            raise HexapodError(f"argument --ground: {g:g} %: {err}") from None
    if args.t_max_run is not None:
        p = p.with_values(**{"run.duration": args.t_max_run})
    seeds = list(range(args.first_seed, args.first_seed + args.seeds))
    show = not args.no_progress and sys.stdout.isatty()
    grounds = args.ground or [100.0 * p.ground.scale]
    t_maxes = args.t_max_list or [p.actuator.t_max]
    if len(grounds) > 1 or len(args.spread) > 1 or len(t_maxes) > 1:
        return _grid(args, p, controllers, seeds, grounds, t_maxes, show)
    p = p.with_values(**{"ground.scale": grounds[0] / 100.0})
    total = len(seeds) * len(controllers)
    res = monte_carlo(p, controllers, seeds, args.spread[0] / 100.0, backend=_backend(args),
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
          f"{args.spread[0]:g} % (sigma of ln factor, per foot and touchdown), T_max "
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


def _grid(args: argparse.Namespace, p: HexapodParams, controllers: tuple[str, ...],
          seeds: list[int], grounds: list[float], t_maxes: list[float], show: bool) -> int:
    """E8: every (ground, spread, T_max); who has the lower hip errors at each point."""
    from .cmd_experiments import _backend, progress_factory
    from .core.montecarlo import decide, monte_carlo_grid

    if len(controllers) != 2:
        raise HexapodError("argument --controllers: a grid of grounds/spreads/T_max compares "
                           "exactly two controllers")
    total = (len(seeds) * len(controllers) * len(grounds) * len(args.spread)
             * len(t_maxes))
    grid = monte_carlo_grid(p, controllers, seeds, grounds,
                            [s / 100.0 for s in args.spread], t_maxes,
                            backend=_backend(args),
                            progress=progress_factory(show)("monte carlo grid", total))
    a, b = controllers
    rows = []
    for g in grid:
        d = decide(g.result, a, b)
        rows.append((g, d))
    if args.json:
        doc = {"method": "per point: paired Student t interval (95 %) of the per-seed "
                         f"difference {b} - {a} of trk_xH + eps_yH (common random numbers)",
               "points": [{"ground_percent": g.ground_percent, "spread": g.spread,
                           "t_max": g.t_max, "difference": d.difference.as_dict(),
                           "winner": d.winner, "seeds_needed": d.seeds_needed,
                           **g.result.as_dict()} for g, d in rows]}
        text = json.dumps(doc, indent=1, allow_nan=True)
        if args.json == "-":
            print(text)
            return 0
        Path(args.json).write_text(text)
    print(f"E8: {len(seeds)} seeds ({seeds[0]}..{seeds[-1]}) per point; hip errors "
          f"trk_xH + eps_yH (m), {b} - {a}: paired Student t 95 % interval over the same "
          "seeds (common random numbers)")
    print(f"{'T_max':>6} {'ground %':>9} {'spread %':>9} {a + ' (m)':>18} {b + ' (m)':>18} "
          f"{b + ' - ' + a:>24} {'winner':>10} {'seeds needed':>13}")
    for g, d in rows:
        sa = mean_of(g.result, a)
        sb = mean_of(g.result, b)
        win = d.winner or "undecided"
        need = ("" if d.seeds_needed is None else
                f"{d.seeds_needed}" if d.winner else f"~{d.seeds_needed}")
        print(f"{g.t_max:>6g} {g.ground_percent:>9g} {100 * g.spread:>9g} {sa:>18.5g} "
              f"{sb:>18.5g} {_fmt(d.difference.mean, d.difference.half_width):>24} "
              f"{win:>10} {need:>13}")
    print("seeds needed: for an interval that excludes 0 at the measured mean and spread "
          "(~: more than were run)")
    if args.json and args.json != "-":
        print(f"every run and its ground factors in {args.json}")
    return 0


def mean_of(res: MonteCarloResult, controller: str) -> float:
    """Mean hip errors over the seeds that walked (m)."""
    import numpy as np

    from .core.montecarlo import hip_errors

    v = hip_errors(res, controller)
    v = v[np.isfinite(v)]
    return float(np.mean(v)) if v.size else math.nan


def add_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Register `montecarlo`."""
    from .cmd_experiments import _backend_args

    p = sub.add_parser("montecarlo", help="controllers on uneven ground over N seeds: means, "
                       "95 %% intervals, paired differences",
                       description="Each index's mean over the seeds with a 95 % Student t "
                       "interval; each controller's paired difference to the first with a "
                       "paired Student t interval over the same seeds (common random "
                       "numbers: seed k gives every controller the same ground).")
    params_arguments(p)
    p.add_argument("--controllers", default="pd_p,pd_pf",
                   help=f"comma list of {', '.join(CONTROLLERS)} (the first is the baseline "
                   "of the differences)")
    p.add_argument("--seeds", type=whole(1, 100000, "a seed count"), default=20,
                   help="seeds per controller (default 20)")
    p.add_argument("--first-seed", type=whole(0, 2 ** 53 - 100001, "a seed"), default=0,
                   dest="first_seed", help="seeds FIRST .. FIRST+N-1 (default 0)")
    p.add_argument("--spread", type=number_list(0.0, 200.0, "a spread in %"),
                   default=[20.0], help="sigma of ln(ground factor) in %% (0 = uniform "
                   "ground; default 20); a comma list runs each (E8)")
    p.add_argument("--ground", type=number_list(0.0, 1e6, "a ground percentage",
                                                lo_open=True),
                   help="nominal ground in %% of the base values (default: the params "
                   "file's); a comma list runs each (E8)")
    p.add_argument("--t-max-list", type=number_list(0.0, math.inf, "a T_max in N m",
                                                    lo_open=True),
                   dest="t_max_list", help="T_max values (N m), each a grid point (E8)")
    p.add_argument("--t-run", type=number(0.0, 1e5, "a duration in s", lo_open=True),
                   dest="t_max_run", metavar="SECONDS",
                   help="simulated seconds per run (default run.duration)")
    p.add_argument("--json", metavar="FILE",
                   help="write every run with its ground factors to FILE ('-': print the "
                   "JSON instead of the table)")
    _backend_args(p)
    p.set_defaults(func=_cmd_montecarlo)


__all__ = ["add_parser", "controllers_arg", "whole"]
