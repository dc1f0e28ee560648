"""Subcommands `sweep`, `tune` and `reproduce`; registers `analyze` and `animate` too."""
from __future__ import annotations

import argparse
import csv
import json
import math
import os
import sys
from pathlib import Path
from typing import Any, Callable, TextIO

import numpy as np

from hexapod_common.core.errors import HexapodError

from .cli_args import params_arguments, params_from_args, parse_range, print_tuning
from .cmd_controllers import controller_list, preload
from hexapod_metrics.core.indices import INDEX_NAMES


#: tqdm's layout with the remaining time spelled out.
BAR_FORMAT = ("{desc}: {percentage:3.0f}%|{bar}| {n_fmt}/{total_fmt} "
              "[{elapsed} elapsed, ETA {remaining}, {rate_fmt}]")


def progress_factory(enabled: bool, stream: TextIO | None = None
                     ) -> Callable[[str, int], Callable[[int], None]]:
    """A tqdm bar with an ETA per labelled piece of work, on ``stream`` (stderr); silent when
    disabled or when the stream is not a terminal (a log file or a pipe gets no bars)."""
    out = sys.stderr if stream is None else stream
    try:
        enabled = enabled and out.isatty()
    except (AttributeError, ValueError):  # closed or not a real stream
        enabled = False

    def make(label: str, total: int) -> Callable[[int], None]:
        if not enabled:
            return lambda n: None
        from tqdm import tqdm

        try:  # a terminal that reports no size (a bare pty) would get an empty bar
            sized = os.get_terminal_size(out.fileno()).columns > 0
        except (AttributeError, OSError, ValueError):
            sized = False
        bar = tqdm(total=total, desc=label, unit="run", file=out, leave=True,
                   dynamic_ncols=sized, ncols=None if sized else 100,
                   bar_format=BAR_FORMAT)

        def update(n: int) -> None:
            bar.update(n)
            if bar.n >= total:
                bar.close()
        return update
    return make


def _backend_args(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--backend", choices=["processes", "inline", "dask"], default=None,
                        help="where runs execute (default: local processes; dask if --dask)")
    parser.add_argument("--dask", metavar="ADDRESS",
                        help="scheduler address of an existing Dask cluster (tcp://host:port), "
                             "or local:N to start a cluster of N workers on this machine")
    parser.add_argument("--no-progress", action="store_true",
                        help="no progress bars (there are none when stderr is not a terminal)")


def _backend(args: argparse.Namespace):  # type: ignore[no-untyped-def]
    """The backend the options name; its workers stop when the command ends."""
    import atexit

    from .core.parallel import ProcessBackend, make_backend

    name = args.backend or ("dask" if args.dask else "processes")
    backend = make_backend(name, args.dask)
    if hasattr(backend, "close"):
        atexit.register(backend.close)
    if isinstance(backend, ProcessBackend):
        backend.start()  # before any progress bar's thread: its workers can then be forked
    return backend


def _floats(text: str, option: str = "") -> list[float]:
    """'10:1000:21' (log-spaced), 'a:b:n:lin', or a comma list (cli_args.parse_range); a bad
    one raises HexapodError naming ``option``."""
    try:
        return parse_range(text)
    except ValueError as err:
        raise HexapodError(f"argument {option}: {err}" if option else str(err)) from None


def _cmd_sweep(args: argparse.Namespace) -> int:
    from hexapod_bringup import plots
    from .core.experiments import ground_sweep, t_max_sweep

    if args.range is None:
        args.range = "10:1000:21" if args.kind == "ground" else "100:400:13:lin"
    _floats(args.range, "--range")
    _floats(args.t_max_list, "--t-max-list")
    controllers = tuple(controller_list(args.controllers, "--controllers"))
    p = params_from_args(args)
    backend = _backend(args)
    prog = progress_factory(not args.no_progress)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    print(f"writing results and plots into {out.resolve()}", flush=True)
    runs = 3 if args.check else 1
    results = []
    if args.kind == "ground":
        for t_max in _floats(args.t_max_list):
            n = len(_floats(args.range)) * len(controllers) * runs
            res = ground_sweep(p, _floats(args.range), t_max, controllers=controllers,
                               backend=backend, check=args.check,
                               progress=prog(f"ground sweep T_max {t_max:g}", n))
            results.append((f"ground_tmax{t_max:g}", res, 100.0,
                            "% of base ground (K_x, K_y, B_x, B_y)", True))
    else:
        vals = _floats(args.range)
        res = t_max_sweep(p, vals, p.ground.scale, controllers=controllers, backend=backend,
                          check=args.check,
                          progress=prog("T_max sweep", len(vals) * len(controllers) * runs))
        results.append(("tmax", res, 1.0, "T_max (N m)", False))
    figures: list[plots.SweepFigure] = []
    for tag, res, xs, xl, logx in results:
        rows = res.rows()
        with (out / f"sweep_{tag}.csv").open("w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
        (out / f"sweep_{tag}.json").write_text(json.dumps(rows, indent=1, default=float))
        figures += [(res, (name,), out / f"sweep_{tag}_{name}.png", f"{name}: {tag}",
                     dict(x_scale=xs, x_label=xl, log_x=logx)) for name in INDEX_NAMES]
        print(f"{res.variable} sweep ({', '.join(f'{k}={v:g}' for k, v in res.fixed.items())})")
        print(f"{'value':>10} {'controller':>10} " + " ".join(f"{n:>10}" for n in INDEX_NAMES)
              + (" converged" if args.check else ""))
        for r in rows:
            vals = " ".join(f"{r[n]:>10.4g}" if not math.isnan(r[n]) else f"{'diverged':>10}"
                            for n in INDEX_NAMES)
            if args.check:
                vals += "  yes" if r["converged"] else f"  NO ({r['unconverged']})"
            print(f"{r[res.variable] * xs:>10.4g} {r['controller']:>10} {vals}")
    plots.sweep_plots(figures, backend)
    print(f"results and plots in {out}")
    return 0


def _cmd_converge(args: argparse.Namespace) -> int:
    from hexapod_control.core.closed_loop import Case

    from .core.convergence import REFINEMENTS, check_cases, tolerance

    preload(args.controller)
    p = params_from_args(args)
    if args.backend is None and not args.dask:
        args.backend = "inline"  # a handful of runs: one batch in this process
    controllers = controller_list(args.controller or p.run.controller)
    total = len(controllers) * len(REFINEMENTS)
    checks = check_cases([Case(p, c) for c in controllers], p.run.duration, _backend(args),
                         progress_factory(not args.no_progress)("convergence", total))
    doc = {}
    print(f"dt = {p.sim.dt:g} s, control period = {p.sim.control_period:g} s "
          f"({1.0 / p.sim.control_period:g} Hz), T_max = {p.actuator.t_max:g} N m, "
          f"ground = {100 * p.ground.scale:g} %")
    for c, cv in zip(controllers, checks):
        doc[c] = cv.as_dict()
        print(f"\n{c}: {'CONVERGED' if cv.converged else 'NOT CONVERGED'}"
              + (f" ({', '.join(cv.unconverged())})" if not cv.converged else ""))
        print(f"{'index':<8} {'dt':>12} {'dt/2':>12} {'dt/4':>12} {'dt/2->dt/4':>11} verdict")
        for n in INDEX_NAMES:
            vals = "".join(f"{getattr(r, n):>13.6g}" if r else f"{'diverged':>13}"
                           for r in cv.runs)
            ch = cv.change(n)
            ok = cv.index_converged(n)
            tol = "" if cv.diverged else f" (tolerance {tolerance(n, getattr(cv.runs[2], n)):.3g})"
            print(f"{n:<8}{vals} {100 * ch:>9.3g} %  {'ok' if ok else 'MOVES'}{tol}")
    if args.json:
        Path(args.json).write_text(json.dumps(doc, indent=1, default=float))
    return 0 if all(cv.converged for cv in checks) or not args.strict else 1


def _cmd_tune(args: argparse.Namespace) -> int:
    from .core.experiments import default_grid, tune

    controller_list(args.controller)
    if args.method == "cmaes":
        from .cmd_cmaes import tune_cmaes_command

        return tune_cmaes_command(args, _backend(args), progress_factory)
    p = params_from_args(args)
    grid = default_grid(p, args.controller, _floats(args.factors, "--factors"))
    for item in args.grid:
        name, _, values = item.partition("=")
        grid[name.strip()] = _floats(values, "--grid")
    total = int(np.prod([len(v) for v in grid.values()])) + 1
    res = tune(p, args.controller, grid, backend=_backend(args),
               progress=progress_factory(not args.no_progress)(f"tuning {args.controller}", total))
    print(f"{args.controller}: {len(res.gains)} gain sets, {res.rejected_diverged} diverged, "
          f"{res.rejected_not_walking} not walking (rejected)")
    print_tuning(res)
    if args.json:
        Path(args.json).write_text(json.dumps({
            "controller": args.controller, "grid": res.grid, "best": res.best,
            "best_score": res.best_score, "reference": res.reference,
            "reference_score": res.reference_score,
            "rejected_diverged": res.rejected_diverged,
            "rejected_not_walking": res.rejected_not_walking,
            "all": [{"gains": g, "score": None if math.isnan(s) else s,
                     "status": o.status} for g, o, s in zip(res.gains, res.outcomes,
                                                             res.scores)]}, indent=1))
    return 0


def _cmd_reproduce(args: argparse.Namespace) -> int:
    from .report import Plan, reproduce

    p = params_from_args(args)
    plan = Plan.quick() if args.quick else Plan()
    print(f"writing the report into {Path(args.out).resolve()}", flush=True)
    readme = Path(args.readme) if args.readme else None
    if readme is not None:
        from .report_headline import BEGIN

        if not readme.is_file() or BEGIN not in readme.read_text():
            raise HexapodError(f"argument --readme: {readme} is not a file with the headline "
                               f"marker {BEGIN}")
    verdicts = reproduce(p, Path(args.out), _backend(args), plan,
                         progress_factory(not args.no_progress))
    if readme is not None:
        from .report_headline import write_readme

        doc = json.loads((Path(args.out) / "results.json").read_text())
        write_readme(readme, doc["claims"])
        print(f"headline written into {readme}")
    for v in verdicts:
        print(f"{v.claim} {v.status.upper()}: {v.statement}")
        print(f"    {v.evidence}")
        if v.windows:
            print(f"    every window, paper's indices: {v.windows}")
            print(f"    every window, stationary indices: {v.stationary}")
    print(f"report written to {Path(args.out) / 'README.md'}")
    return 0


_Opt = tuple[tuple[str, ...], dict[str, Any]]


def _opt(*flags: str, **kw: Any) -> _Opt:
    return flags, kw


#: The experiment commands: name, help, handler, own options (each also takes the params
#: options and the backend options).
COMMANDS: tuple[tuple[str, str, Callable[[argparse.Namespace], int], tuple[_Opt, ...]], ...] = (
    ("sweep", "ground or T_max sweep for the controllers (E2-E4)", _cmd_sweep, (
        _opt("kind", choices=["ground", "tmax"], help="what to sweep"),
        _opt("--range", default=None,
             help="values: 'lo:hi:n' log-spaced, 'lo:hi:n:lin', or 'a,b,c'; ground in "
             "%% (default 10:1000:21), T_max in N m (default 100:400:13:lin)"),
        _opt("--t-max-list", default="400,170", dest="t_max_list",
             help="ground sweep: T_max values, one sweep each (default 400,170)"),
        _opt("--controllers", default="pd_p,pd_pf",
             help="comma-separated registered controllers or module:Class paths"),
        _opt("--out", default="sweeps", help="output directory (CSV, JSON, PNG; default "
             "./sweeps, printed at the start)"),
        _opt("--check", action="store_true",
             help="rerun every point at dt/2 and dt/4 and report its convergence"))),
    ("converge", "rerun a case at dt/2 and dt/4: is it converged?", _cmd_converge, (
        _opt("--controller", default="both",
             help="controller(s), comma-separated, or 'both' = pd_p,pd_pf"),
        _opt("--json", help="write the three runs and the verdicts to this file"),
        _opt("--strict", action="store_true",
             help="exit with code 1 if a controller's indices are not converged"))),
    ("tune", "gain search (E5): brute-force grid, or CMA-ES", _cmd_tune, (
        _opt("--controller", required=True,
             help="a registered controller or module:Class whose gains kp1..kd2 to tune"),
        _opt("--method", choices=["grid", "cmaes"], default="grid",
             help="grid (default: every set of --factors/--grid) or cmaes (CMA-ES over "
             "log factors of the params file's gains, at most --budget runs)"),
        _opt("--budget", type=int, default=62,
             help="cmaes: at most this many evaluations (default 62, a tenth of the "
             "default grid's 625 sets)"),
        _opt("--gains", default=None, help="cmaes: the gains searched (default "
             "kp1,kd1,kp2,kd2, and alpha for a controller that has one: pd_alpha)"),
        _opt("--sigma0", type=float, default=0.8,
             help="cmaes: initial step in ln(gain) (default 0.8, about x/÷ 2.2)"),
        _opt("--seed", type=int, default=1, help="cmaes: seed of the search (default 1)"),
        _opt("--factors", default="0.5,0.75,1,1.5,2",
             help="default grid: each gain of the params file times these factors"),
        _opt("--grid", action="append", default=[], metavar="GAIN=VALUES",
             help="explicit values for one gain, e.g. kp1=5000:160000:16"),
        _opt("--json", help="write every evaluated set to this JSON file"))),
    ("reproduce", "run E1-E9, check every point in dt, write the report", _cmd_reproduce, (
        _opt("--out", default="report", help="report directory (default ./report: from the "
             "repository's root this regenerates the committed report; printed at the start)"),
        _opt("--quick", action="store_true",
             help="a few points per experiment (every point still checked in dt)"),
        _opt("--readme", metavar="FILE", default=None,
             help="also write the claims' headline table between the headline markers of "
             "FILE (the repository's README.md)"))),
)


def add_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Register sweep, converge, tune and reproduce."""
    for name, help_text, func, options in COMMANDS:
        p = sub.add_parser(name, help=help_text)
        params_arguments(p)
        for flags, kw in options:
            p.add_argument(*flags, **kw)
        _backend_args(p)
        p.set_defaults(func=func)


__all__ = ["add_parser", "progress_factory"]
