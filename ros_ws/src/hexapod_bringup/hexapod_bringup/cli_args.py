"""Command-line values that mean what they say, shared by the `hexapod` CLI and the graph
launcher (`scripts/run_graph.sh`), so both accept and refuse the same input in the same words.

* :class:`OneLineParser`: argparse, but a usage error is one line (``prog: error: ...``)
  and exit code 2; ``--opt=value`` and ``--opt value`` both work (argparse's own).
* :func:`param_value`: an option that sets one model parameter: the text is read as a number
  (``1e6``, ``inf``/``.inf``) and checked against that parameter's spec; the error names the
  option and the parameter (``argument --t-max: parameter 'actuator.t_max' = 'abc' is
  invalid: allowed float in (0, inf] (a string, where a float is expected)``).
* :func:`number`: a plain finite number within bounds (``--switch-at``, ``--timeout``).
* :func:`value_range`: ``a:b:n`` (log-spaced), ``a:b:n:lin`` or a comma list, validated.
* :func:`params_arguments` / :func:`params_from_args`: the params-file options every engine
  command shares, and the parameters they give.
"""
from __future__ import annotations

import argparse
import math
import sys
from typing import TYPE_CHECKING, Any, Callable, NoReturn

from hexapod_common.core.errors import HexapodError, ParameterError

if TYPE_CHECKING:
    from hexapod_common.core.params import HexapodParams

# The parameter table (core/params.py: PyYAML, the controllers' entry points) is imported
# where it is used, not here: `hexapod switch` and `hexapod status` parse their options
# with this module and must start in a fraction of a second.


def read_number(text: str) -> float:
    """A number written as text, read as the params file reads it (params.read_number)."""
    from hexapod_common.core.params import read_number as read

    return read(text)


class OneLineParser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one line on stderr and exit code 2."""

    def error(self, message: str) -> NoReturn:
        """Print ``prog: error: message`` (one line, with a hint to --help) and exit 2."""
        message = " ".join(message.split())
        print(f"{self.prog}: error: {message} (see --help)", file=sys.stderr)
        sys.exit(2)


def param_value(name: str) -> Callable[[str], Any]:
    """An argparse ``type`` for an option that sets parameter ``name`` (checked by its spec)."""
    from hexapod_common.core.params import SPECS, check_value, wrong_type

    spec = SPECS[name]

    def convert(text: str) -> Any:
        if spec.kind is str:
            value: Any = text
        else:
            try:
                value = read_number(text)
            except ValueError:
                raise argparse.ArgumentTypeError(str(wrong_type(name, spec, text))) from None
        try:
            return check_value(name, value)
        except ParameterError as err:
            raise argparse.ArgumentTypeError(str(err)) from None

    convert.__name__ = name  # argparse names the type in some messages
    return convert


def number(lo: float = -math.inf, hi: float = math.inf, what: str = "a number",
           lo_open: bool = False) -> Callable[[str], float]:
    """An argparse ``type``: a finite number in [lo, hi] (or (lo, hi] with ``lo_open``)."""
    left = "(" if lo_open else "["

    def convert(text: str) -> float:
        try:
            value = read_number(text)
        except ValueError:
            value = math.nan
        ok = math.isfinite(value) and lo <= value <= hi and not (lo_open and value == lo)
        if not ok:
            raise argparse.ArgumentTypeError(
                f"{text!r} is not {what} in {left}{lo:g}, {hi:g}]")
        return value

    convert.__name__ = what
    return convert


#: ``--control-rate HZ`` (sim.control_period = 1/HZ), in the CLI and the graph launcher.
control_rate = number(0.0, 1e6, "a control rate (Hz)", lo_open=True)


def parse_range(text: str) -> list[float]:
    """'10:1000:21' (log-spaced), 'a:b:n:lin' (linear) or '1,2,3'; ValueError says why."""
    import numpy as np  # here: `hexapod switch` imports this module and must start fast

    form = "'LO:HI:N' (log-spaced), 'LO:HI:N:lin' or a comma list of numbers"
    if ":" in text:
        parts = text.split(":")
        if len(parts) not in (3, 4) or (len(parts) == 4 and parts[3] != "lin"):
            raise ValueError(f"{text!r} is not {form}")
        try:
            lo, hi = read_number(parts[0]), read_number(parts[1])
            n = int(parts[2])
        except ValueError:
            raise ValueError(f"{text!r} is not {form}") from None
        if not (math.isfinite(lo) and math.isfinite(hi)):
            raise ValueError(f"{text!r}: the ends must be finite numbers")
        if n < 1 or (n == 1 and lo != hi):
            raise ValueError(f"{text!r}: N = {n} points cannot span {lo:g}..{hi:g} "
                             f"(N >= 2, or N = 1 with LO = HI)")
        if hi < lo:
            raise ValueError(f"{text!r}: HI = {hi:g} is below LO = {lo:g}")
        if len(parts) == 4:
            return [float(v) for v in np.linspace(lo, hi, n)]
        if lo <= 0:
            raise ValueError(f"log-spaced range {text!r} needs positive ends (or add ':lin')")
        return [float(v) for v in np.geomspace(lo, hi, n)]
    items = [t.strip() for t in text.split(",")]
    if not any(items) or not all(items):
        raise ValueError(f"{text!r} is not {form}")
    try:
        values = [read_number(t) for t in items]
    except ValueError:
        raise ValueError(f"{text!r} is not {form}") from None
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f"{text!r}: every value must be a finite number")
    return values


def value_range(text: str) -> list[float]:
    """argparse ``type`` form of :func:`parse_range`."""
    try:
        return parse_range(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None




def params_arguments(parser: argparse.ArgumentParser) -> None:
    """The options every engine command shares: params file and the usual overrides."""
    parser.add_argument("--params", help="ROS 2 params file (default: the shipped base case)")
    parser.add_argument("--t-max", type=param_value("actuator.t_max"), dest="t_max",
                        help="actuator saturation T_max in N m ('inf' for ideal actuators)")
    parser.add_argument("--ground-scale", type=param_value("ground.scale"), dest="ground_scale",
                        help="factor on all four ground parameters (1.0 = 100 %%)")
    parser.add_argument("--control-rate", type=control_rate, dest="control_rate", metavar="HZ",
                        help="control rate in Hz: sim.control_period = 1/HZ, a whole number "
                        "of physics steps (10000 = control at every step)")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                        help="override any parameter by its dotted name, e.g. gait.velocity=0.8")


def overrides_from_args(args: argparse.Namespace) -> dict[str, Any]:
    """Dotted parameter name -> value from --set, --t-max, --ground-scale and
    --control-rate (the CLI's and the graph launcher's one reading of them)."""
    overrides: dict[str, Any] = {}
    for item in args.set:
        name, sep, text = item.partition("=")
        if not sep or not name.strip():
            raise HexapodError(f"--set expects NAME=VALUE, got {item!r}")
        overrides[name.strip()] = parse_value(text.strip())
    if args.t_max is not None:
        overrides["actuator.t_max"] = args.t_max
    if args.ground_scale is not None:
        overrides["ground.scale"] = args.ground_scale
    if args.control_rate is not None:
        if not args.control_rate > 0 or args.control_rate == float("inf"):
            raise HexapodError(f"--control-rate: expected a positive number of Hz, got "
                               f"{args.control_rate:g}")
        overrides["sim.control_period"] = 1.0 / args.control_rate
    return overrides


def params_from_args(args: argparse.Namespace) -> HexapodParams:
    """Load the params file and apply --t-max, --ground-scale and --set overrides."""
    from hexapod_common.core.params import load_params

    return load_params(args.params, **overrides_from_args(args))


def parse_value(text: str) -> Any:
    """A --set/--change value: YAML (numbers, booleans, lists), else the text itself."""
    from hexapod_common.core.params import parse_yaml

    try:
        return parse_yaml(text)
    except Exception:  # noqa: BLE001 (any YAML error: then it is text)
        return text


__all__ = ["OneLineParser", "control_rate", "number", "overrides_from_args", "param_value",
           "params_arguments",
           "params_from_args", "parse_range", "parse_value", "read_number", "value_range"]


def print_tuning(res: Any) -> None:
    """The best gain set of a tuning (grid or CMA-ES) next to the params file's, with
    trk_xH + eps_yH of each and the improvement."""
    print("best:        " + ", ".join(f"{k}={v:.6g}" for k, v in res.best.items()) +
          f"  trk_xH+eps_yH = {res.best_score:.5g} m")
    print("params file: " + ", ".join(f"{k}={v:.6g}" for k, v in res.reference.items()) +
          f"  trk_xH+eps_yH = {res.reference_score:.5g} m")
    print(f"the best set beats the params file's gains by {100 * res.improvement:.3g} %")
