"""`hexapod controllers`: the registered controllers, their parameters, defaults and ranges;
and the one place the other commands turn a controller option into checked names."""
from __future__ import annotations

import argparse
import json

from hexapod_common.core.errors import HexapodError, ParameterError

from .cli_args import params_arguments, params_from_args


def controller_list(text: str, option: str = "--controller") -> list[str]:
    """Comma-separated controller names ('both' = pd_p,pd_pf), each a registered name or a
    module:Class path (loaded now, so that its parameters can be --set); an unknown one is
    a one-line error listing the registered names."""
    from hexapod_control.core import registry

    names = ["pd_p", "pd_pf"] if text == "both" else [c.strip() for c in text.split(",")]
    for name in names:
        try:
            registry.load(name)
        except ParameterError as err:
            raise HexapodError(f"argument {option}: {err}") from None
    return names


def preload(argv_controllers: str | None) -> None:
    """Load module:Class controllers named on the command line before the parameters are
    read (their groups become known to --set and the params file)."""
    if argv_controllers and ":" in argv_controllers:
        controller_list(argv_controllers)


def _cmd_controllers(args: argparse.Namespace) -> int:
    from hexapod_control.core import registry

    p = params_from_args(args)
    names = list(registry.names())
    for extra in args.load:
        names += [n for n in controller_list(extra, "--load") if n not in names]
    doc = {}
    for name in names:
        cls = registry.load(name)
        info = registry.describe(name, p)
        doc[name] = {"class": f"{cls.__module__}:{cls.__qualname__}",
                     "summary": (cls.__doc__ or "").strip().splitlines()[0]
                     if cls.__doc__ else "",
                     "compiled": registry.is_compiled(name, p),
                     "parameters": [i._asdict() for i in info]}
    if args.json:
        print(json.dumps(doc, indent=2, default=str))
        return 0
    for name, d in doc.items():
        path = "compiled law" if d["compiled"] else "per-tick Python law + drive"
        print(f"{name}  ({d['class']}; {path})")
        if d["summary"]:
            print(f"  {d['summary']}")
        for i in d["parameters"]:
            print(f"  {i['name']:<22} {i['kind']:<5} default {i['default']!s:<10} "
                  f"{i['allowed']:<26} {i['description']}")
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Register `hexapod controllers`."""
    sp = sub.add_parser("controllers", help="list the registered controllers and their "
                        "parameters (defaults from the params file, ranges)")
    params_arguments(sp)
    sp.add_argument("--load", action="append", default=[], metavar="MODULE:CLASS",
                    help="also list this module:Class controller (repeatable)")
    sp.add_argument("--json", action="store_true", help="print JSON instead of a table")
    sp.set_defaults(func=_cmd_controllers)


__all__ = ["add_parser", "controller_list", "preload"]
