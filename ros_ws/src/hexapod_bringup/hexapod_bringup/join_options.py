"""The launcher's side of controllers that join the graph (docs/controllers.md).

* ``--no-builtin pd_p,pd_pf``: start without one or both built-in controller nodes (their
  places can be taken by nodes that join);
* ``--controller NAME`` may name a controller that is not built in: the sim then starts
  with ``NAME`` in charge and tick 0 waits (``startup_timeout``) for its node; for a
  registered plug-in (e.g. ``pd_alpha``) the launcher starts that node (:func:`plugins`);
* :func:`join_lines`: how an external node joins this run (key file, domain, helper).
"""
from __future__ import annotations

import argparse
from collections.abc import Mapping

from hexapod_common.core.controller_names import check_name, engine_names, node_of
from hexapod_common.core.errors import HexapodError

#: The Fast DDS profile of the run (its transports, lease and the tick topics' partition).
PROFILE_ENV = "FASTRTPS_DEFAULT_PROFILES_FILE"

GRAPH_WAIT = ("trajectory_generator", "pd_p_controller", "pd_pf_controller", "metrics")


def builtin_list(text: str) -> tuple[str, ...]:
    """argparse type of ``--no-builtin``: a comma list of built-in controllers."""
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    bad = [n for n in names if n not in engine_names()]
    if not names or bad:
        raise argparse.ArgumentTypeError(
            f"{text!r}: expected a comma list of {', '.join(engine_names())}")
    return names


#: What a module:Class path on the graph's command line is told (one line).
REGISTER_HINT = ("the graph runs a plug-in by its registered name: declare it in your "
                 "package's setup.py, entry_points={{'hexapod.controllers': ['NAME = "
                 "{module}:{cls}']}}, install the package with "
                 "`scripts/install_controller.sh PATH` and use --controller NAME "
                 "(docs/controllers.md, 'Engine plug-ins'); `hexapod simulate --controller "
                 "{text}` runs it as it is")


def controller_arg(text: str) -> str:
    """argparse type of ``--controller``: a controller name (built in or joining); a
    module:Class path is refused with how to register it."""
    if ":" in text:
        module, _, cls = text.partition(":")
        raise argparse.ArgumentTypeError(f"{text!r} is a module:Class path: " +
                                         REGISTER_HINT.format(module=module, cls=cls,
                                                              text=text))
    try:
        return check_name(text, "controller")
    except HexapodError as err:
        raise argparse.ArgumentTypeError(f"{text!r} is not a controller name ({err})") from err


def add_options(p: argparse.ArgumentParser) -> None:
    """Add ``--no-builtin`` to the launcher's parser."""
    p.add_argument("--no-builtin", dest="no_builtin", type=builtin_list, default=(),
                   metavar="LIST", help="do not start these built-in controllers (comma "
                   "list of pd_p, pd_pf): nodes that join take their place "
                   "(docs/controllers.md)")


def builtins(args: argparse.Namespace) -> tuple[str, ...]:
    """The built-in controllers this run starts."""
    return tuple(c for c in engine_names() if c not in args.no_builtin)


def plugins(args: argparse.Namespace) -> tuple[str, ...]:
    """Registered plug-in controllers (``hexapod controllers``; not pd_p / pd_pf) this run
    starts a node for: ``--controller`` when it names one (the node is named as the
    controller and runs its law per tick, as the engine does)."""
    from hexapod_common.core.params import controller_names

    c = args.controller
    return (c,) if c not in engine_names() and c in controller_names() else ()


def check(args: argparse.Namespace) -> None:
    """Refuse contradictory options (HexapodError, one line)."""
    started = builtins(args)
    if args.controller in engine_names() and args.controller not in started:
        raise HexapodError(f"argument --controller: {args.controller} is not started "
                         f"(--no-builtin {','.join(args.no_builtin)}): name the controller "
                         f"that joins, e.g. --controller my_controller")
    if args.switch_to and args.switch_to not in started:
        raise HexapodError(f"argument --switch-to: {args.switch_to} is not started "
                         f"(--no-builtin): switch to a joined controller with "
                         f"`hexapod switch NAME` instead")


def default_switch_to(args: argparse.Namespace) -> str | None:
    """The scripted switch's target: --switch-to, else the other built-in if started."""
    if args.switch_to:
        return str(args.switch_to)
    other = "pd_p" if args.controller == "pd_pf" else "pd_pf"
    return other if other in builtins(args) and other != args.controller else None


def wait_for(args: argparse.Namespace, extra: tuple[str, ...] = ()) -> str:
    """The sim's ``wait_for``: the nodes started, plus a joining controller in charge."""
    nodes = [n for n in GRAPH_WAIT
             if not (n.endswith("_controller") and n[:-11] not in builtins(args))]
    if args.controller not in engine_names():
        nodes.append(node_of(args.controller))
    return ",".join(nodes + list(extra))


def join_lines(env: Mapping[str, str], domain: str) -> list[str]:
    """How an external controller node joins this run."""
    # here, not at the top: `hexapod switch` parses its argument with controller_arg and
    # must start fast (msg_auth loads numpy)
    from hexapod_common.core.msg_auth import AUTH_ENV, KEY_ENV

    if env.get(AUTH_ENV, "on").lower() == "off":
        key = f"{AUTH_ENV}=off (no key: messages are not authenticated)"
    else:
        key = f"{KEY_ENV}={env.get(KEY_ENV, '?')}"
    profile = env.get(PROFILE_ENV)
    dds = f" {PROFILE_ENV}={profile}" if profile else ""
    return [f"run_graph: a controller node joins with ROS_DOMAIN_ID={domain} {key}{dds} "
            f"(Python: hexapod_common.auth.signer reads the key from {KEY_ENV}; the DDS "
            f"profile puts the tick topics in the run's partition; other languages: "
            f"docs/controllers.md), then `scripts/hexapod switch NAME`"]


__all__ = ["add_options", "builtin_list", "builtins", "check", "controller_arg",
           "default_switch_to", "join_lines", "plugins", "wait_for"]
