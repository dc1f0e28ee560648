"""The one launcher of the ROS 2 node graph (``scripts/run_graph.sh`` is a thin wrapper).

Runs the simulator, the trajectory generator, both controllers and the recorder (and
optionally the markers node) as processes of one :class:`~.cmd_graph.GraphProcesses`,
waits for the sim to finish (``--duration``) or for Ctrl-C / SIGTERM, stops every node,
prints the sim's tick counts, the messages the sim and the recorder dropped and the
publishers outside the graph they saw (:func:`inputs_lines`), the indices of each
controller segment (noting live parameter changes, :func:`indices_lines`) and the bag's
path, and exits with a code that says what went wrong (:data:`EXIT_CODES`).

Before any node starts, the settings are checked the way ``hexapod simulate`` checks them
(the same parser, the same messages, :mod:`.cli_args`): a bad option, an unknown or
misspelt key, an empty or wrongly shaped params file is one line and exit code 2. The
nodes then read one params file written by this launcher from the validated values
(numbers as numbers, no ``-p`` type surprises) into a private run directory (``mkdtemp``,
mode 0700) that also holds the Fast DDS profile and the sim's summary.

While the graph runs, any node that exits is reported at once (name, exit code or
signal); a dead recorder stops the run (nothing would be recorded). At the end the sim's
summary (``summary_path``) says whether a fallback happened and which ticks were not
commanded by the controller in charge: a cycle with such ticks is labelled ``mixed`` (or
``fallback`` if all of its ticks were), never with a controller's name alone.
"""
from __future__ import annotations

import argparse
import itertools
import json
import math
import os
import shutil
import signal
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import yaml

from hexapod_control.core.waits import parse as parse_waits
from hexapod_common.core import topics as T
from hexapod_common.core.errors import HexapodError
from hexapod_common.core.controller_names import node_of
from hexapod_sim.core.uneven_ground import check_seed, check_spread
from hexapod_common.runtime.rt_sched import HOW_TO_PERMIT, MAX_PRIORITY, realtime_permitted
from hexapod_common.runtime.liveness import PIDS_ENV
from hexapod_common.core.params import (CONTROLLERS, MODES, SPECS, HexapodParams,
                                        default_params_path, load_params, read_params_file)

from . import join_options as join
from .cli_args import OneLineParser, control_rate, number, overrides_from_args, param_value
from .cmd_graph import RT_NODES, GraphProcesses

#: Exit codes of the launcher, one per cause (the first that applies, in this order).
EXIT_CODES: dict[str, int] = {
    "ok": 0,
    "bad settings": 2,           # bad option, params file or parameter (nothing started)
    "disk full": 5,              # the recorder ran out of disk space
    "recorder failed": 4,        # the recorder (metrics) died or exited non-zero
    "node died": 3,              # another node died or exited non-zero during the run
    "diverged": 6,               # the model blew up (the sim says so and stops)
    "fallback": 7,               # the controller in charge went silent: damping fallback
    "fallen": 8,                 # a scored gait cycle was not a walk (no indices for it)
    "interrupted": 130,          # Ctrl-C / SIGTERM of a run with a set duration
}
#: Order in which causes decide the exit code.
PRECEDENCE = ("disk full", "recorder failed", "node died", "diverged", "fallback",
              "fallen", "interrupted")
#: Stop order: the sim first, the recorder last (it drains its queues).
STOP_ORDER = ("hexapod_sim", "trajectory_generator", "pd_p_controller", "pd_pf_controller",
              "markers", "foxglove_bridge", "metrics")
#: Words in the recorder's log (or its exit) that mean the disk is full.
DISK_FULL_MARKERS = ("No space left on device", "ENOSPC", "disk full")
#: Free bytes below which a failed recorder's disk counts as full.
DISK_FULL_BYTES = 1 << 20
#: Exit code of a recorder whose bag could not be written to the end (disk full, quota, I/O
#: error): metrics_node.EXIT_RECORDING_FAILED; its log line says which.
RECORDER_WRITE_FAILED_EXIT = 3


class LaunchError(HexapodError):
    """The graph cannot be started as asked (bad bag path, params file, option)."""


@dataclass
class Outcome:
    """What happened in one run: causes (each with its line) and the node exit codes."""

    causes: dict[str, str] = field(default_factory=dict)
    codes: dict[str, int | None] = field(default_factory=dict)

    def add(self, cause: str, line: str) -> None:
        """Record ``cause`` (first line per cause kept)."""
        self.causes.setdefault(cause, line)

    def exit_code(self) -> int:
        """The code of the first cause in :data:`PRECEDENCE` (0 if none)."""
        for cause in PRECEDENCE:
            if cause in self.causes:
                return EXIT_CODES[cause]
        return 0


# --------------------------------------------------------------------------- options


def build_parser(prog: str = "run_graph") -> argparse.ArgumentParser:
    """The launcher's options (``--opt value`` and ``--opt=value``)."""
    p = OneLineParser(prog=prog, description="Run the ROS 2 node graph, print the indices "
                      "of each controller segment and the bag's path.",
                      epilog="Exit codes: " + ", ".join(f"{c} {n}" for n, c in
                                                        EXIT_CODES.items()))
    p.add_argument("--controller", type=join.controller_arg, default="pd_pf",
                   help="controller in charge at the start (default pd_pf; a controller "
                   "that joins: tick 0 waits for its node)")
    p.add_argument("--switch-to", choices=CONTROLLERS, dest="switch_to",
                   help="controller to hand over to (default: the other one)")
    p.add_argument("--switch-at", dest="switch_at",
                   type=number(0.0, SPECS["run.duration"].hi or math.inf,
                               "a simulated time (s)"),
                   help="simulated time of the hand-over (default: half the duration)")
    p.add_argument("--no-switch", action="store_true", dest="no_switch",
                   help="keep the first controller all along")
    p.add_argument("--mode", choices=MODES, default="lockstep", help="graph mode")
    p.add_argument("--rt-priority", dest="rt_priority", type=rt_priority, metavar="N",
                   help=f"SCHED_FIFO priority of the control path (the sim's, the "
                   f"controllers' and the trajectory generator's main and Fast DDS "
                   f"threads; the other nodes' Fast DDS threads); default "
                   f"{REALTIME_PRIORITY} in realtime mode, 0 (normal scheduling) in "
                   f"lockstep; needs CAP_SYS_NICE or an rtprio limit, else a warning")
    p.add_argument("--duration", type=_duration, default=6.0,
                   help="simulated duration in s (default 6); 0 = until Ctrl-C")
    p.add_argument("--ground-scale", dest="ground_scale", type=param_value("ground.scale"),
                   help="factor on the four ground parameters (1.0 = 100 %%)")
    p.add_argument("--t-max", dest="t_max", type=param_value("actuator.t_max"),
                   help="actuator saturation T_max in N m (.inf = ideal actuators)")
    p.add_argument("--control-rate", dest="control_rate", type=control_rate, metavar="HZ",
                   help="control rate in Hz (sets sim.control_period = 1/HZ; default: the "
                   "params file's (10 kHz) in lockstep, the same as `hexapod simulate`; "
                   f"{REALTIME_RATE_HZ:g} with PD-P&F's force loop in the drive in realtime "
                   "mode)")
    p.add_argument("--ground-seed", dest="ground_seed", type=_seed, metavar="K",
                   help="uneven ground: every foot's factors per touchdown from seed K, as "
                   "`hexapod montecarlo --seeds 1 --first-seed K` (replays it bit for bit in "
                   "lockstep)")
    p.add_argument("--ground-spread", dest="ground_spread", type=_spread, default=0.0,
                   metavar="PCT", help="uneven ground: spread in %% (sigma of ln factor x "
                   "100, as montecarlo's --spread; default 0)")
    p.add_argument("--params", help="ROS 2 params file (default: the shipped base experiment)")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="override any parameter by its dotted name (repeatable)")
    p.add_argument("--bag", help="bag directory (default bags/<YYYYmmdd-HHMMSS>); node logs "
                   "go to BAG_logs")
    p.add_argument("--sim-time", action="store_true", dest="sim_time",
                   help="run the other nodes with use_sim_time:=true (~10 %% slower)")
    p.add_argument("--markers", action="store_true",
                   help="also run the markers node (/hexapod/markers for Foxglove)")
    p.add_argument("--foxglove", nargs="?", const=8765, default=None, metavar="PORT",
                   type=port, help="serve the graph's topics live to Foxglove on "
                   "ws://localhost:PORT (default 8765); implies --markers; layout: "
                   "docs/foxglove/hexapod_layout.json")
    join.add_options(p)
    return p


#: Realtime mode's default control rate (Hz), with PD-P&F's force loop in the drive: the
#: params file's 10 kHz over topics runs at ~0.14x real time here. Measured (hexapod
#: simulate, 3 s, base ground): PD-P&F with its force loop in the drive at 1 kHz comes within
#: 0.04 % (E_av, T_L) and 0.9 mm (tracking errors) of the 10 kHz over-topics numbers; at
#: 1000 % ground within 1.4 % and 1.9 mm (docs/benchmarks.md, "Drive placement").
#: Lockstep keeps the params file's rate: every front end's default scenario is the same.
REALTIME_RATE_HZ = 1000.0


def convergence_note(p: HexapodParams) -> str:
    """What E6 says about the numbers of a run at ``p``'s control rate."""
    rate = 1.0 / p.sim.control_period
    if p.pd_pf.force_loop == "drive" and rate >= 1000.0 - 1e-6:
        return ("PD-P&F's force loop in the drive (pd_pf.force_loop=drive): within 1 % and "
                "1 mm of the 10 kHz over-topics numbers on the base ground and softer, not "
                "on 1000 % ground (docs/benchmarks.md)")
    if rate >= 10000.0 - 1e-6:
        return "the rate of the paper experiments: dt-converged over E6's whole range"
    if rate >= 2000.0 - 1e-6 and p.ground.scale <= 1.0:
        return ("dt-converged on the base ground and softer (E6); harder ground needs "
                "5-10 kHz")
    return ("NOT dt-converged in general at this rate (E6): PD-P&F's numbers depend on the "
            "physics step; check with `hexapod converge --control-rate HZ`")


#: The control path's SCHED_FIFO priority in realtime mode (hexapod_common/runtime/rt_sched.py):
#: low among real-time priorities (the kernel's threaded interrupts run at 50).
REALTIME_PRIORITY = 20


def rt_priority(text: str) -> int:
    """A SCHED_FIFO priority, 0..98 (0 = normal scheduling)."""
    value = number(0.0, MAX_PRIORITY, "a SCHED_FIFO priority")(text)
    if value != int(value):
        raise argparse.ArgumentTypeError(f"{text!r} is not a SCHED_FIFO priority (an integer "
                                         f"in [0, {MAX_PRIORITY}])")
    return int(value)


def port(text: str) -> int:
    """A TCP port number, 0..65535 (0 = any free one)."""
    if not text.isdigit() or int(text) > 65535:
        raise argparse.ArgumentTypeError(f"{text!r} is not a port number in [0, 65535]")
    return int(text)


def _seed(text: str) -> int:
    """argparse type of ``--ground-seed``: a whole number in [0, 2^53)."""
    try:
        return check_seed(int(text), "--ground-seed")
    except (ValueError, HexapodError) as err:
        raise argparse.ArgumentTypeError(f"{text!r} is not a seed (a whole number in "
                                         f"[0, 2^53))") from err


def _spread(text: str) -> float:
    """argparse type of ``--ground-spread``: percent, 0..200 (sigma of ln factor x 100)."""
    try:
        return 100.0 * check_spread(float(text) / 100.0, "--ground-spread")
    except (ValueError, HexapodError) as err:
        raise argparse.ArgumentTypeError(f"{text!r} is not a spread in % (0 to 200)") from err


def _duration(text: str) -> float:
    """0 (until Ctrl-C) or a valid run.duration."""
    try:
        if float(text) == 0.0:
            return 0.0
    except ValueError:
        pass
    return float(param_value("run.duration")(text))


def settings(args: argparse.Namespace) -> tuple[HexapodParams, dict[str, Any]]:
    """The validated parameters of the run and the node parameters from the params file.

    Raises ParameterError / ParamsFileError (one line, named key) exactly as the CLI does.
    """
    overrides = overrides_from_args(args)
    join.check(args)
    if args.controller in CONTROLLERS:  # a joining controller is set on the sim alone
        overrides["run.controller"] = args.controller
    overrides["sim.mode"] = args.mode
    if args.duration > 0:
        overrides["run.duration"] = args.duration
    if args.mode == "realtime" and args.params is None:
        if "sim.control_period" not in overrides:
            overrides["sim.control_period"] = 1.0 / REALTIME_RATE_HZ
            if "pd_pf.force_loop" not in overrides:
                overrides["pd_pf.force_loop"] = "drive"
    path = args.params or default_params_path()
    p = load_params(path, **overrides)
    node_params = {k: v for k, v in read_params_file(path).items() if k not in SPECS}
    if args.switch_at is not None and args.duration > 0 and args.switch_at > args.duration:
        raise LaunchError(f"argument --switch-at: {args.switch_at:g} s is after the end of "
                          f"the run (--duration {args.duration:g} s)")
    return p, node_params


def write_params_file(path: Path, p: HexapodParams, node_params: dict[str, Any]) -> None:
    """The nodes' params file: every model parameter as validated, plus the file's node
    parameters (all in ``/**``); floats stay floats (``1.0``, ``.inf``)."""
    tree: dict[str, Any] = {}
    for name, value in p.to_flat().items():
        group, _, key = name.partition(".")
        tree.setdefault(group, {})[key] = value
    tree.update(node_params)
    path.write_text(yaml.safe_dump({"/**": {"ros__parameters": tree}}, sort_keys=False))


# --------------------------------------------------------------------------- the run


def fresh_bag_path(parent: Path, stamp: str) -> Path:
    """``parent/stamp``, else ``stamp-2``, ``stamp-3``, ...: the first whose log directory
    (``<bag>_logs``) this call creates, so that two runs started in the same second never
    share a bag (the second one's recorder then refused the path and the run failed)."""
    parent.mkdir(parents=True, exist_ok=True)
    for i in itertools.count(1):
        bag = (parent / (stamp if i == 1 else f"{stamp}-{i}")).resolve()
        if bag.exists():
            continue
        try:
            Path(f"{bag}_logs").mkdir()
        except FileExistsError:
            continue
        return bag
    raise AssertionError("unreachable")


class Launcher:
    """One run of the graph from validated settings."""

    def __init__(self, args: argparse.Namespace, p: HexapodParams,
                 node_params: dict[str, Any]) -> None:
        self.args = args
        self.p = p
        root = Path.cwd()
        if args.bag:
            self.bag = Path(args.bag).resolve()
            if self.bag.exists():
                raise LaunchError(f"bag directory {self.bag} already exists")
        else:
            self.bag = fresh_bag_path(root / "bags", time.strftime("%Y%m%d-%H%M%S"))
        self.logs = Path(f"{self.bag}_logs")
        self.run_dir = Path(tempfile.mkdtemp(prefix="hexapod_run_"))  # 0700
        self.params_file = self.run_dir / "params.yaml"
        write_params_file(self.params_file, p, node_params)
        self.summary_file = self.run_dir / "sim_summary.json"
        self.graph: GraphProcesses | None = None
        self.stop_signal: int | None = None
        self.outcome = Outcome()

    # ------------------------------------------------------------------ start
    def sim_overrides(self) -> list[str]:
        """The sim's own parameters: what it waits for, stop, scripted switch, summary file.
        Each is set here, whatever a params file says of it (a `ros2 param dump` of a
        running sim carries that run's: its wait_for, switch_to, stop_at_end)."""
        a = self.args
        extra = [f"summary_path:={self.summary_file}"]
        if a.ground_seed is not None:
            extra += [f"ground_seed:={a.ground_seed}",
                      f"ground_spread:={a.ground_spread / 100.0!r}"]
        markers = a.markers or a.foxglove is not None
        # tick 0 waits for the markers node too, so the markers cover the run from t = 0
        extra.append(f"wait_for:={join.wait_for(a, ('markers',) if markers else ())}")
        if a.controller not in CONTROLLERS:
            extra.append(f"run.controller:={a.controller}")
        switch_to = join.default_switch_to(a) if not a.no_switch else None
        at = None
        if a.duration > 0:
            extra.append("stop_at_end:=true")
            if switch_to:
                at = a.switch_at if a.switch_at is not None else a.duration / 2
        else:  # until stopped: the sim's run.duration says so (0)
            extra += ["stop_at_end:=false", "run.duration:=0.0"]
            if switch_to and a.switch_at is not None:
                at = a.switch_at
        if at is not None:
            extra += [f"switch_at:={float(at)!r}", f"switch_to:={switch_to}"]
        else:
            extra.append("switch_to:=''")  # none (YAML: the empty string)
        return extra

    def describe(self) -> str:
        """One line: what this run does."""
        a = self.args
        d = f"{a.mode} mode, {a.controller} in charge"
        switch_to = join.default_switch_to(a)
        if not a.no_switch and (a.duration > 0 or a.switch_at is not None) and switch_to:
            at = a.switch_at if a.switch_at is not None else a.duration / 2
            d += f", {switch_to} from t = {at:g} s"
        if a.ground_seed is not None:
            d += f", uneven ground seed {a.ground_seed} spread {a.ground_spread:g} %"
        return d + (f", {a.duration:g} s" if a.duration > 0 else ", until Ctrl-C")

    def scheduling(self) -> int:
        """The control path's SCHED_FIFO priority for this run (0: normal scheduling), and
        one line saying so (or why not)."""
        a = self.args
        priority = a.rt_priority
        if priority is None:
            priority = REALTIME_PRIORITY if self.p.sim.mode == "realtime" else 0
        if priority == 0:
            return 0
        if not realtime_permitted(priority):
            print(f"run_graph: warning: SCHED_FIFO priority {priority} is not permitted here "
                  f"({HOW_TO_PERMIT}): the control path runs with normal scheduling and "
                  f"realtime mode may miss deadlines", file=sys.stderr, flush=True)
            return 0
        print(f"run_graph: SCHED_FIFO priority {priority} for the control path "
              f"({', '.join(RT_NODES)}: main and Fast DDS threads) and the other nodes' Fast "
              f"DDS threads", flush=True)
        return priority

    def start(self) -> None:
        """Start the nodes (the sim last: it waits for the others' endpoints)."""
        self.bag.parent.mkdir(parents=True, exist_ok=True)
        self.logs.mkdir(parents=True, exist_ok=True)
        self.graph = g = GraphProcesses(self.logs, params=str(self.params_file),
                                        use_sim_time=self.args.sim_time,
                                        rt_priority=self.scheduling())
        print(f"run_graph: ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID', '0')}: "
              f"{self.describe()} (node logs in {self.logs})", flush=True)
        rate = 1.0 / self.p.sim.control_period
        chosen = (" (realtime mode's default; --control-rate HZ for another)"
                  if self.p.sim.mode == "realtime" and self.args.params is None
                  and self.args.control_rate is None
                  and rate == REALTIME_RATE_HZ else "")
        print(f"run_graph: control at {rate / 1000:g} kHz{chosen}, physics step "
              f"{self.p.sim.dt:g} s: {convergence_note(self.p)}", flush=True)
        g.start("metrics", f"bag_path:={self.bag}")
        g.start("trajectory_generator")
        for c in join.builtins(self.args):
            g.start(f"{c}_controller")
        for c in join.plugins(self.args):
            g.start(node_of(c))
        for line in join.join_lines(g.env, os.environ.get("ROS_DOMAIN_ID", "0")):
            print(line, flush=True)
        if self.args.markers or self.args.foxglove is not None:
            g.start("markers")
        if self.args.foxglove is not None:
            g.start("foxglove_bridge", f"port:={self.args.foxglove}")
            print(f"run_graph: Foxglove live view on ws://localhost:{self.args.foxglove} "
                  "(layout: docs/foxglove/hexapod_layout.json)", flush=True)
        # The sim judges the launcher's nodes alive by their processes (runtime/liveness.py)
        pids = self.logs / "pids.json"
        g.env[PIDS_ENV] = str(pids)
        self._write_pids(pids)
        g.start("hexapod_sim", *self.sim_overrides())
        self._write_pids(pids)

    def _write_pids(self, path: Path) -> None:
        """Node name -> pid of every process started, and the launcher's (atomically)."""
        g = self.graph
        assert g is not None
        tmp = path.with_suffix(".tmp")
        tmp.write_text(json.dumps({n: proc.pid for n, proc in g.procs.items()}
                                  | {"launcher": os.getpid()}))
        os.replace(tmp, path)

    # ------------------------------------------------------------------ watch
    def watch(self) -> None:
        """Until the sim ends or a stop signal comes: report every node that exits."""
        g = self.graph
        assert g is not None
        seen: set[str] = set()
        while self.stop_signal is None:
            sim = g.poll("hexapod_sim")
            for name in list(g.procs):
                code = g.poll(name)
                if code is None or name in seen or name == "hexapod_sim":
                    continue
                seen.add(name)
                self._node_ended(name, code, during_run=True)
            if "metrics" in seen and sim is None:
                print("run_graph: the recorder is gone: stopping the graph", file=sys.stderr)
                break
            if sim is not None:
                break
            time.sleep(0.1)

    def _node_ended(self, name: str, code: int | None, during_run: bool) -> None:
        self.outcome.codes[name] = code
        how = _how(code)
        log = self.logs / f"{name}.log"
        if name == "metrics":
            if self._disk_full(code):
                self.outcome.add("disk full", f"the recorder ran out of disk space ({how}; "
                                 f"log: {log})")
            elif during_run or code != 0:
                what = (" (its bag could not be written to the end)"
                        if code == RECORDER_WRITE_FAILED_EXIT else "")
                self.outcome.add("recorder failed", f"the recorder (metrics) {how}{what} "
                                 f"{'during the run' if during_run else 'at the end'} "
                                 f"(log: {log})")
        elif during_run or code not in (0, None):
            self.outcome.add("node died", f"{name} {how} during the run (log: {log})")
        if during_run:
            print(f"run_graph: {name} {how} during the run (log: {log})", file=sys.stderr,
                  flush=True)

    def _disk_full(self, code: int | None) -> bool:
        """Did the recorder stop because the bag's disk is full?  Its exit code, the words
        of its log, or (a log on the same full disk may say nothing) the free space."""
        if code in (0, None):
            return False
        try:
            if shutil.disk_usage(self.bag.parent).free < DISK_FULL_BYTES:
                return True
            text = (self.logs / "metrics.log").read_text(errors="replace")
        except OSError:
            return False
        return any(m in text for m in DISK_FULL_MARKERS)

    # ------------------------------------------------------------------ stop
    def stop(self) -> None:
        """Stop every node (sim first, recorder last) and collect the exit codes."""
        g = self.graph
        if g is None:
            return
        plugin_nodes = [node_of(c) for c in join.plugins(self.args)]
        for name in STOP_ORDER[:-1] + tuple(plugin_nodes) + STOP_ORDER[-1:]:
            if name not in g.procs:
                continue
            was_running = g.procs[name].poll() is None
            code = g.stop(name, timeout=30.0 if name == "metrics" else 10.0)
            if name in self.outcome.codes:  # reported when it ended during the run
                continue
            if name == "hexapod_sim":
                self._sim_ended(code)
            elif was_running and code in (0, -signal.SIGINT, -signal.SIGTERM):
                self.outcome.codes[name] = code
            else:
                self._node_ended(name, code, during_run=not was_running)
        g.stop_all()

    def _sim_ended(self, code: int | None) -> None:
        self.outcome.codes["hexapod_sim"] = code
        log = self.logs / "hexapod_sim.log"
        if code == 1 and "diverg" in log.read_text(errors="replace").lower():
            self.outcome.add("diverged", f"the model diverged: hexapod_sim stopped (log: {log})")
        elif code not in (0, None):
            self.outcome.add("node died", f"hexapod_sim {_how(code)} (log: {log})")

    # ------------------------------------------------------------------ report
    def sim_summary(self) -> dict[str, Any] | None:
        """The sim's summary (None if it wrote none)."""
        try:
            return json.loads(self.summary_file.read_text())
        except (OSError, ValueError):
            return None

    def report(self) -> list[str]:
        """Lines: the sim's figures, the indices (labelled), the causes, the bag."""
        lines = []
        summary = self.sim_summary()
        if summary is not None:
            lines.append(
                f"  sim: stopped at tick {summary['tick']} (t = "
                f"{summary['tick'] * summary['control_period']:.3f} s): {summary['missed']} "
                f"missed, {summary['late']} late, {summary['fallback_episodes']} fallback "
                f"episodes, {len(summary['switches'])} switches"
                + (f", {summary['recorder_holds']} holds for the recorder "
                   f"({summary.get('recorder_held_s', 0.0):.2f} s)"
                   if summary.get("recorder_holds") else ""))
            if summary["fallback_episodes"]:
                ranges = summary["fallback_ticks"]
                self.outcome.add("fallback", f"{summary['fallback_episodes']} fallback "
                                 f"episode(s): joint damping from tick "
                                 f"{ranges[0][0] if ranges else '?'} (the controller in "
                                 f"charge went silent)")
            if summary["missed"] or summary["fallback_episodes"]:
                lines += self.controller_waits()
        lines += inputs_lines(summary, self.bag / "indices.json")
        short, lost = bag_shortfall(summary, self.bag / "indices.json")
        if short:
            self.outcome.add("recorder failed", "the bag lacks states of the sim's ticks: "
                             f"{short} (log: {self.logs / 'metrics.log'})")
            lines.append(f"  bag: INCOMPLETE: {short}")
        if lost:
            lines.append(f"  bag: lost on the way to the recorder (holes in the publishers' "
                         f"sequence numbers): {lost}")
        lines += indices_lines(self.bag / "indices.json")
        return lines

    def controller_waits(self) -> list[str]:
        """Lines: what each controller's states waited for (its end summary, core/waits.py),
        the controllers' side of missed ticks."""
        lines = []
        g = self.graph
        for name in (f"{c}_controller" for c in CONTROLLERS):
            try:
                waits = parse_waits(g.log(name)) if g is not None else None
            except OSError:  # not started
                waits = None
            cause = waits.cause() if waits is not None else ""
            if cause:
                lines.append(f"  {name}: {cause}")
        return lines

    def cleanup(self) -> None:
        """Remove the private run directory."""
        shutil.rmtree(self.run_dir, ignore_errors=True)


def _how(code: int | None) -> str:
    if code is None:
        return "did not stop"
    if code < 0:
        try:
            return f"was killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"was killed by signal {-code}"
    return f"exited with code {code}"


def inputs_lines(summary: dict[str, Any] | None, indices: Path) -> list[str]:
    """Lines: the messages the sim and the recorder dropped (per topic and cause) and the
    publishers outside the graph they saw, from the sim's summary and ``indices.json``."""
    docs = [("sim", summary or {})]
    try:
        docs.append(("recorder", json.loads(indices.read_text())))
    except (OSError, ValueError):
        pass
    dropped = []
    outside: dict[str, set[str]] = {}
    for who, doc in docs:
        counts = doc.get("dropped") or {}
        if counts:
            dropped.append(f"{who} {sum(counts.values())} ("
                           + ", ".join(f"{k} {n}" for k, n in sorted(counts.items())) + ")")
        for topic, names in (doc.get("outside_publishers") or {}).items():
            outside.setdefault(topic, set()).update(names)
    lines = ["  inputs: " + ("dropped " + "; ".join(dropped) if dropped
                             else "no message dropped")]
    if len(dropped) == 2 and len({sum((d.get("dropped") or {}).values()) for _, d in docs}) > 1:
        lines.append("    (each node counts what reached its own reader: one that matched a "
                     "publisher later, or whose queue a flood overran, counts fewer)")
    lines.append("  publishers outside the graph: " + ("; ".join(
        f"{t}: {', '.join(sorted(n))}" for t, n in sorted(outside.items())) or "none"))
    if (summary or {}).get("authentication") == "off":
        lines.append("  authentication: off (HEXAPOD_AUTH=off): any process on this "
                     "ROS_DOMAIN_ID could drive the graph, and none was named for it")
    return lines


#: Topics the sim publishes once per tick from tick 0: a bag of a run lacks none of them.
PER_TICK_TOPICS = (T.JOINT_STATES, T.FOOT_FORCES, T.HIP_STATES)


def bag_shortfall(summary: dict[str, Any] | None, indices: Path) -> tuple[str, str]:
    """(what the bag lacks of the sim's per-tick messages, what the recorder counted as lost
    on the way), each empty if nothing (or if either file is missing: reported elsewhere).

    The first compares the recorder's counts (``indices.json``; it was waited for before
    tick 0) with the sim's ticks: ``tick`` + 1 of each after a finished run, ``tick`` after
    an interrupted one (its last tick's messages may not be out). The second is the holes
    in the senders' sequence numbers (``msg_auth.Verifier.missing``): said, not a failure,
    since any holder of the run's key can make them."""
    try:
        doc = json.loads(indices.read_text())
    except (OSError, ValueError):
        return "", ""
    lost = (doc.get("recording") or {}).get("lost_in_transit") or {}
    lost_text = ", ".join(f"{t} {n}" for t, n in sorted(lost.items()))
    if summary is None or not summary.get("started", True):
        return "", lost_text
    expected = int(summary["tick"]) + (1 if summary.get("finished", True) else 0)
    held = doc.get("messages") or {}
    short = ", ".join(f"{t} {held.get(t, 0)} of {expected}" for t in PER_TICK_TOPICS
                      if held.get(t, 0) < expected)
    return short, lost_text


def _changes_in(changes: list[dict[str, Any]], t0: float, t1: float) -> list[dict[str, Any]]:
    """The parameter changes at times in (t0, t1]."""
    return [c for c in changes if t0 < c["t"] <= t1 + 1e-12]


def _change_text(changes: list[dict[str, Any]]) -> str:
    return ", ".join(f"{c['name']} = {c['value']!r} at {c['t']:.3f} s" for c in changes)


def fallen_cycles(path: Path) -> list[str]:
    """'cycle k [t_a, t_b] s: why' of every cycle of ``indices.json`` that was not a walk."""
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError):
        return []
    return [f"cycle {c['cycle']} [{c['t_a']:g}, {c['t_b']:g}] s: {c['fallen']}"
            for c in doc.get("cycles", ()) if c.get("fallen")]


def indices_lines(path: Path) -> list[str]:
    """The table of indices per controller segment from ``indices.json``: the per-cycle mean
    over the gait cycles the controller commanded entirely (``cycles.segments``; model.md:
    not the index of their union, so a segment of 3 cycles and one of 2 compare), with the
    drift columns; a segment none of whose cycles it commanded entirely names the label of
    its last one (``hexapod_common.core.labels``: ``fallback``, ``held``, ``mixed(...)``)."""
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError):
        return [f"run_graph: no indices.json in {path.parent} (see the metrics log)"]
    names = doc["index_names"]
    changes = doc.get("parameter_changes") or []
    t_of = {c["cycle"]: (c["t_a"], c["t_b"]) for c in doc.get("cycles", ())}
    fell_in = {c["cycle"]: c for c in doc.get("cycles", ()) if c.get("fallen")}
    out = ["indices per controller segment (per-cycle mean of the full gait cycles it "
           "commanded):",
           f"  {'controller':<24} {'segment [s]':<16} {'cycles':<12}"
           + "".join(f"{n:>11}" for n in names)]
    for s in doc["segments"]:
        c = s["last_full_cycle"]
        seg = f"[{s['t_start']:g}, {s['t_end']:g}]"
        own = [k for k in s.get("mean_cycles", ()) if k in t_of]
        if c is None:
            out.append(f"  {s['controller']:<24} {seg:<16} no full gait cycle")
            continue
        if s.get("fallen"):  # not a walk: no numbers (hexapod_metrics.core.walking)
            out.append(f"  {s['controller']:<24} {seg:<16} {'':<12}  no indices: {s['fallen']}")
            continue
        mean = s.get("per_cycle_mean")
        if mean is None or not own:
            label = c.get("label", s["controller"])
            out.append(f"  {label:<24} {seg:<16} {'':<12}  no cycle commanded entirely by "
                       f"{s['controller']} (the last: {label})")
            continue
        span = f"{len(own)}: {own[0]}-{own[-1]}" if len(own) > 1 else f"1: {own[0]}"
        row = "".join(f"{mean[n]:>11.4g}" for n in names)
        out.append(f"  {s['controller']:<24} {seg:<16} {span:<12}{row}")
        # cycles of the segment it did not command that were not a walk (a fallback's):
        # left out of the mean, and named here without numbers
        fell = [fell_in[k] for k in s.get("cycles", ()) if k in fell_in and k not in own]
        if fell:
            c0 = fell[0]
            out.append(f"    ^ {len(fell)} other cycles of this segment fallen (no indices), "
                       f"the first: cycle {c0['cycle']} ({c0.get('label', '?')}): "
                       f"{c0['fallen'].removeprefix('fallen: ')}")
        # live parameter changes: the mean then mixes two settings; before its cycles (in
        # this segment) they are the new setting's, not the segment start's
        t_a, t_b = t_of[own[0]][0], t_of[own[-1]][1]
        inside = _changes_in(changes, t_a, t_b - 1e-9)
        before = _changes_in(changes, s["t_start"] - 1e-9, t_a)
        if inside:
            out.append(f"    ^ these cycles span a live parameter change (hexapod analyze "
                       f"splits the segment there): {_change_text(inside)}")
        if before:
            out.append(f"    ^ after a live parameter change in this segment: "
                       f"{_change_text(before)}")
    if changes:  # every one, also those of a controller not in charge (its own gains)
        out.append("live parameter changes (each from the tick its node applied it): "
                   + ", ".join(f"{c['name']} = {c['value']!r} at {c['t']:.3f} s "
                               f"(tick {c['tick']}, {c['node']})" for c in changes))
    return out


def run(argv: Sequence[str] | None = None, prog: str = "run_graph") -> int:
    """Parse, validate, launch, watch, stop, report; the exit code (:data:`EXIT_CODES`)."""
    args = build_parser(prog).parse_args(argv)
    try:
        p, node_params = settings(args)
        launcher = Launcher(args, p, node_params)
    except HexapodError as err:
        print(f"{prog}: error: {err}", file=sys.stderr)
        return EXIT_CODES["bad settings"]
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    os.environ.setdefault("RMW_FASTRTPS_PUBLICATION_MODE", "SYNCHRONOUS")

    def on_signal(signum: int, frame: Any) -> None:
        if launcher.stop_signal is None:
            launcher.stop_signal = signum
            print(f"{prog}: {signal.Signals(signum).name}: stopping the graph",
                  file=sys.stderr, flush=True)

    old = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        try:
            launcher.start()
        except OSError as err:  # the bag's or the logs' directory cannot be made
            print(f"{prog}: error: cannot start the graph: {err}", file=sys.stderr)
            return EXIT_CODES["bad settings"]
        launcher.watch()
        launcher.stop()
        fell = fallen_cycles(launcher.bag / "indices.json")
        if fell:
            launcher.outcome.add("fallen", f"{len(fell)} scored gait cycles were not a walk, "
                                 f"the first: {fell[0]}")
        if launcher.stop_signal is not None and args.duration > 0:
            name = signal.Signals(launcher.stop_signal).name
            launcher.outcome.add("interrupted", f"stopped by {name} before the end of the run")
        for line in launcher.report():
            print(line)
        for cause, line in launcher.outcome.causes.items():
            print(f"{prog}: {cause} (exit {EXIT_CODES[cause]}): {line}", file=sys.stderr)
        print(f"bag: {launcher.bag}", flush=True)
        return launcher.outcome.exit_code()
    finally:
        if launcher.graph is not None and launcher.graph.procs:
            launcher.graph.stop_all(order=STOP_ORDER)
        for s, h in old.items():
            signal.signal(s, h)
        launcher.cleanup()


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point (``python -m hexapod_bringup.graph_launcher``)."""
    return run(argv)


if __name__ == "__main__":
    sys.exit(main())
