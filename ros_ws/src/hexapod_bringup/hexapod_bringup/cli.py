"""`hexapod`: the project's command line (simulate, analyze, sweep, tune, reproduce...).

Each subcommand lives in a module that registers itself with :func:`register`-style
``add_parser(subparsers)`` functions listed in :data:`COMMAND_MODULES`; this file only wires
them, turns the project's errors into one line on stderr and a non-zero exit.
"""
from __future__ import annotations

import argparse
import importlib
import json
import sys
from typing import Any, Callable, Sequence

from hexapod_common.core.errors import HexapodError

from .cli_args import OneLineParser, param_value, params_arguments, params_from_args, parse_value

#: Modules that contribute subcommands (``add_parser(subparsers)``); missing ones are skipped
#: so that a partial install still offers what it has.
COMMAND_MODULES = ("hexapod_bringup.graph_cli", "hexapod_bringup.cmd_experiments",
                   "hexapod_bringup.cmd_analyze", "hexapod_bringup.animation",
                   "hexapod_bringup.cmd_controllers", "hexapod_bringup.cmd_montecarlo")
#: Subcommands that talk to a running graph: parsed and run by graph_cli alone, without
#: importing the engine, numba and the plots (a second of CPU that a realtime graph on the
#: same cores would feel).
GRAPH_COMMANDS = ("switch", "status")


def _fmt(v: float) -> str:
    return f"{v:.6g}"


def _cmd_simulate(args: argparse.Namespace) -> int:
    from hexapod_metrics.core.indices import REPORTED_NAMES, INDEX_UNITS
    from .core.simulate import simulate

    from .cmd_controllers import controller_list, preload

    preload(args.controller)
    p = params_from_args(args)
    controllers = controller_list(args.controller or p.run.controller)
    results = {}
    switches = []
    for item in args.switch:
        when, sep, who = item.partition(":")
        try:
            t_switch = float(when)
        except ValueError:
            t_switch = float("nan")
        if not sep or not (0.0 <= t_switch <= (args.duration or p.run.duration)):
            raise HexapodError(f"--switch expects TIME:CONTROLLER with TIME in [0, duration = "
                               f"{args.duration or p.run.duration:g}] s, got {item!r}")
        controller_list(who, f"--switch {item!r}")
        switches.append((t_switch, who))
    changes = []
    for item in args.change:
        when, sep, assignment = item.partition(":")
        name, eq, text = assignment.partition("=")
        if not sep or not eq:
            raise HexapodError(f"--change expects TIME:NAME=VALUE, got {item!r}")
        changes.append((float(when), {name.strip(): parse_value(text.strip())}))
    for c in controllers:
        sim = simulate(p, c, args.duration, switches=switches, param_changes=changes)
        if args.bag:
            from hexapod_metrics.core.recording import write_run_bag

            write_run_bag(sim.run, f"{args.bag}_{c}" if len(controllers) > 1 else args.bag)
        results[c] = sim
    if args.json:
        doc = {c: {"status": s.outcome.status, "reason": s.outcome.reason,
                   "window_s": list(s.outcome.window),
                   "t_max": p.actuator.t_max, "ground_scale": p.ground.scale,
                   "indices": s.indices.as_dict() if s.indices else None,
                   "cycles": [{"cycle": k, "t_a": k * p.cycle_time,
                               "t_b": (k + 1) * p.cycle_time,
                               **(i.as_dict() if i else {"status": "fallen"})}
                              for k, i in enumerate(s.outcome.cycles)]}
               for c, s in results.items()}
        print(json.dumps(doc, indent=2, allow_nan=True))
        return _simulate_exit(results)
    print(f"T_max = {p.actuator.t_max:g} N m, ground = {100 * p.ground.scale:g} %, "
          f"window = [{results[controllers[0]].outcome.window[0]:g}, "
          f"{results[controllers[0]].outcome.window[1]:g}] s")
    if switches:
        print("switches: " + ", ".join(f"{c} at {t:g} s" for t, c in switches) +
              " (columns name the starting controller)")
    if changes:
        t_a, t_b = results[controllers[0]].outcome.window
        for t, values in changes:
            where = ("inside the window: the indices mix both settings" if t_a < t < t_b
                     else "before the window: the indices are the new setting's"
                     if t <= t_a else "after the window: the indices do not see it")
            print("parameter change: " + ", ".join(f"{n} = {v!r}" for n, v in values.items())
                  + f" at {t:g} s ({where})")
    header = f"{'index':<8} {'unit':<12}" + "".join(f"{c:>14}" for c in controllers)
    print(header)
    for name in REPORTED_NAMES:
        row = f"{name:<8} {INDEX_UNITS[name]:<12}"
        for c in controllers:
            idx = results[c].indices
            row += f"{_fmt(getattr(idx, name)) if idx else results[c].outcome.status:>14}"
        print(row)
    for c in controllers:
        if results[c].outcome.reason:
            print(f"{c}: {results[c].outcome.reason}")
    return _simulate_exit(results)


#: Exit code of ``hexapod simulate`` when a run was not a walk (graph_launcher's "fallen").
EXIT_FALLEN = 8


def _simulate_exit(results: dict[str, Any]) -> int:
    """0, or :data:`EXIT_FALLEN` if any run's evaluation window was not a walk."""
    return EXIT_FALLEN if any(s.outcome.status == "fallen" for s in results.values()) else 0


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser."""
    parser = OneLineParser(prog="hexapod", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    sp = sub.add_parser("simulate", help="run the in-process engine (no ROS) and print indices")
    params_arguments(sp)
    sp.add_argument("--controller", metavar="NAME[,NAME...]",
                    help="controller(s): registered names (`hexapod controllers`), "
                    "module:Class paths, or 'both' = pd_p,pd_pf (default: run.controller of "
                    "the params file)")
    sp.add_argument("--duration", type=param_value("run.duration"),
                    help="simulated seconds (default run.duration)")
    sp.add_argument("--json", action="store_true", help="print JSON instead of a table "
                    "(the window's indices and every full gait cycle's)")
    sp.add_argument("--bag", help="also write the run as a rosbag2/MCAP bag to this directory")
    sp.add_argument("--switch", action="append", default=[], metavar="TIME:CONTROLLER",
                    help="hand over to CONTROLLER at TIME s (repeatable), as the graph does")
    sp.add_argument("--change", action="append", default=[], metavar="TIME:NAME=VALUE",
                    help="change a ground/actuator/gain parameter from the first tick at or "
                    "after TIME s (repeatable), as a live change in the graph")
    sp.set_defaults(func=_cmd_simulate)
    for name in COMMAND_MODULES:
        try:
            mod = importlib.import_module(name)
        except ModuleNotFoundError as err:
            if err.name != name:
                raise
            continue
        mod.add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point: run a subcommand; project errors become one line and exit code 2."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] in GRAPH_COMMANDS:
        from .graph_cli import main as graph_main

        return graph_main(argv)
    import numpy as np

    from hexapod_metrics.bag import BagError

    args = build_parser().parse_args(argv)
    func: Callable[[argparse.Namespace], int] = args.func
    np.seterr(all="ignore")
    try:
        return func(args)
    except (HexapodError, BagError, ValueError, OSError, ArithmeticError) as err:
        print(f"hexapod {args.command}: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"hexapod {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
