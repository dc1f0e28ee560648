"""`hexapod tune --method cmaes`: E5's objective minimised by CMA-ES (core/cmaes.py)."""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any, Callable

from hexapod_common.core.errors import HexapodError

from .cli_args import params_from_args, print_tuning

#: Largest --budget accepted (runs).
MAX_BUDGET = 100000


def tune_cmaes_command(args: argparse.Namespace, backend: Any,
                       progress_factory: Callable[[bool], Callable[[str, int],
                                                                   Callable[[int], None]]]
                       ) -> int:
    """Run CMA-ES for ``args.controller`` and print the best set next to the params file's."""
    from .core.cmaes import default_names, searchable, tune_cmaes

    if not 2 <= args.budget <= MAX_BUDGET:
        raise HexapodError(f"argument --budget: {args.budget} is not a number of runs in "
                           f"[2, {MAX_BUDGET}]")
    if not (math.isfinite(args.sigma0) and 0.0 < args.sigma0 <= 3.0):
        raise HexapodError(f"argument --sigma0: {args.sigma0:g} is not a step in (0, 3] "
                           f"(ln of a factor)")
    if not 0 <= args.seed < 2 ** 32:
        raise HexapodError(f"argument --seed: {args.seed} is not a whole number in "
                           f"[0, 2^32)")
    p = params_from_args(args)
    names = (default_names(p, args.controller) if args.gains is None
             else tuple(n.strip() for n in args.gains.split(",")))
    allowed = searchable(p, args.controller)
    for n in names:
        if n not in allowed:
            raise HexapodError(f"argument --gains: {n!r} is not a gain of "
                               f"{args.controller} (one of {', '.join(allowed)})")
    show = not args.no_progress and sys.stdout.isatty()
    try:
        res = tune_cmaes(p, args.controller, names, args.budget, args.sigma0, args.seed,
                         backend=backend,
                         progress=progress_factory(show)(f"CMA-ES {args.controller}",
                                                         args.budget))
    except ValueError as err:
        raise HexapodError(str(err)) from None
    print(f"{args.controller}: CMA-ES, {res.evaluations} evaluations "
          f"({res.search.generations} generations), {res.rejected} rejected "
          f"(diverged or not walking)")
    print_tuning(res)
    if args.json:
        Path(args.json).write_text(json.dumps({
            "controller": args.controller, "method": "cmaes", "seed": args.seed,
            "sigma0": args.sigma0, "budget": args.budget, "best": res.best,
            "best_score": res.best_score, "reference": res.reference,
            "reference_score": res.reference_score, "evaluations": res.evaluations,
            "rejected": res.rejected,
            "all": [{"log_factors": x.tolist(), "score": f}
                    for x, f in zip(res.search.xs, res.search.fs)]}, indent=1))
    return 0


__all__ = ["MAX_BUDGET", "tune_cmaes_command"]
