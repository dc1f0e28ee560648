"""Bad settings through both front ends: the `hexapod` CLI and scripts/run_graph.sh.

Every case is refused before anything runs: one line on stderr naming the key or option
(with the nearest known name for a typo), exit code 2, and the same words from both front
ends (they share the parser and the checks). Nothing is started, so no ROS domain is used.
"""
from __future__ import annotations

import contextlib
import io
import os
import subprocess
from pathlib import Path

import pytest

from hexapod_common.core.params import default_params_path

ROOT = Path(__file__).resolve().parents[1]
BASE = default_params_path().read_text()


def hexapod(*args: str) -> subprocess.CompletedProcess:
    """The `hexapod` CLI's entry point (what scripts/hexapod runs), in this process: the
    same code as a subprocess, without a second interpreter start per case."""
    from hexapod_bringup.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(list(args))
        except SystemExit as exc:  # argparse
            code = exc.code if isinstance(exc.code, int) else 2
    return subprocess.CompletedProcess(["hexapod", *args], code, out.getvalue(),
                                       err.getvalue())


def run_graph_script(*args: str) -> subprocess.CompletedProcess:
    """scripts/run_graph.sh itself (set-up check, then the launcher in a process of its own)."""
    env = {**os.environ, "ROS_DOMAIN_ID": "231"}  # never used: nothing may start
    return subprocess.run([str(ROOT / "scripts" / "run_graph.sh"), *args], capture_output=True,
                          text=True, timeout=300, env=env)


def run_graph(*args: str) -> subprocess.CompletedProcess:
    """The launcher run_graph.sh hands its arguments to (``graph_launcher.run``), in this
    process: the same parser and checks, without a bash, a set-up check and an interpreter
    start per case (test_the_script_passes_bad_settings_to_the_launcher runs the script)."""
    from hexapod_bringup.graph_launcher import run

    out, err = io.StringIO(), io.StringIO()
    domain = os.environ.get("ROS_DOMAIN_ID")
    os.environ["ROS_DOMAIN_ID"] = "231"  # never used: nothing may start
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = run(list(args))
            except SystemExit as exc:  # argparse
                code = exc.code if isinstance(exc.code, int) else 2
    finally:
        if domain is None:
            del os.environ["ROS_DOMAIN_ID"]
        else:
            os.environ["ROS_DOMAIN_ID"] = domain
    return subprocess.CompletedProcess(["run_graph", *args], code, out.getvalue(),
                                       err.getvalue())


def one_error_line(r: subprocess.CompletedProcess, prog: str) -> str:
    """The message after '<prog>: error: ' of a one-line, exit-2 failure."""
    assert r.returncode == 2, (r.returncode, r.stdout, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    assert lines[0].startswith(f"{prog}: error: "), lines[0]
    assert "run_graph: ROS_DOMAIN_ID" not in r.stdout  # no node was started
    return lines[0][len(f"{prog}: error: "):]


PARAMS_FILES = [  # (file content, text the one line must hold)
    ("", "is empty"),
    ("42\n", "holds int 42"),
    ("[1, 2]\n", "holds list"),
    ("/**:\n  ros__parameters:\n    ground: 5\n", "'ground' must be a group of parameters"),
    ("/**:\n  ros__parameters:\n    ground:\n      k_y: {a: 1}\n",
     "parameter 'ground.k_y' must be a value"),
    ("/**:\n  other: 1\n", "section '/**' lacks 'ros__parameters'"),
    ("/**:\n  ros__parameters: 3\n", "section '/**' lacks 'ros__parameters'"),
    ("hexapod_smi:\n  ros__parameters:\n    stop_at_end: true\n",
     "unknown section 'hexapod_smi' (did you mean 'hexapod_sim'?)"),
    ("robot: [1, 2\n", "is not valid YAML"),
    (BASE.replace("k_y: 1000000.0", "k_yy: 1000000.0"),
     "parameter 'ground.k_yy' = 1000000.0 is invalid: allowed a known parameter name "
     "(did you mean 'ground.k_y'?)"),
    (BASE.replace("duty_factor:", "dutyfactor:"),
     "parameter 'gait.dutyfactor' = 0.5 is invalid: allowed a known parameter name "
     "(did you mean 'gait.duty_factor'?)"),
    (BASE.replace("    ground:", "    grond:"), "unknown group 'grond' (did you mean 'ground'?)"),
    (BASE.replace("    ground:", "    k_y: 3\n    ground:"),
     "unknown parameter 'k_y' in section '/**' (did you mean 'body.k_y'?)"),
    (BASE.replace("t_max: 400.0", "t_max: fast"),
     "parameter 'actuator.t_max' = 'fast' is invalid: allowed float in (0, inf]"),
    (BASE.replace("body_height: 1.8", "body_height: 1.99"),
     "parameter 'gait.body_height' = 1.99 is invalid"),
    (BASE.replace("step_length: 1.0", "step_length: 4.0").replace("velocity: 1.0",
                                                                    "velocity: 4.0"),
     "parameter 'gait.step_length' = 4.0 is invalid"),
    (BASE.replace("foot_clearance: 0.2", "foot_clearance: 1.8"),
     "parameter 'gait.foot_clearance' = 1.8 is invalid"),
    # the nodes' own parameters: their table (params.NODE_PARAMS) holds type and range
    ("hexapod_sim:\n  ros__parameters:\n    ground_seed: -5\n",
     "node 'hexapod_sim': parameter 'ground_seed' = -5 is invalid"),
    ("hexapod_sim:\n  ros__parameters:\n    ground_spread: 3.5\n",
     "node 'hexapod_sim': parameter 'ground_spread' = 3.5 is invalid"),
    ("markers:\n  ros__parameters:\n    rate: 0\n",
     "node 'markers': parameter 'rate' = 0.0 is invalid: allowed float in (0, 1e+06]"),
    ("markers:\n  ros__parameters:\n    deliver_to: 5\n",
     "node 'markers': parameter 'deliver_to' = 5 is invalid: allowed any str"),
    ("markers:\n  ros__parameters:\n    startup_timeout: .nan\n",
     "node 'markers': parameter 'startup_timeout' = nan is invalid"),
    ("/**:\n  ros__parameters:\n    startup_timeout: -1\n",
     "node 'hexapod_sim': parameter 'startup_timeout' = -1.0 is invalid: allowed float in [0, "),
    ("markers:\n  ros__parameters:\n    lookahead: 2\n",
     "'lookahead' is not a parameter of node 'markers'"),
    ("metrics:\n  ros__parameters:\n    max_bag_size: -1\n",
     "node 'metrics': parameter 'max_bag_size' = -1 is invalid: allowed int in [0, "),
    ("metrics:\n  ros__parameters:\n    batch_interval: fast\n",
     "node 'metrics': parameter 'batch_interval' = 'fast' is invalid"),
    ("foxglove_bridge:\n  ros__parameters:\n    port: 70000\n",
     "node 'foxglove_bridge': parameter 'port' = 70000 is invalid: allowed int in [0, 65535]"),
    ("hexapod_sim:\n  ros__parameters:\n    switch_to: pd_x\n",
     "node 'hexapod_sim': parameter 'switch_to' = 'pd_x' is invalid: allowed one of '', pd_p, "
     "pd_pf"),
    ("pd_p_controller:\n  ros__parameters:\n    autostart: 1\n",
     "node 'pd_p_controller': parameter 'autostart' = 1 is invalid: allowed true or false"),
    ("trajectory_generator:\n  ros__parameters:\n    lookahead: 1.5\n",
     "node 'trajectory_generator': parameter 'lookahead' = 1.5 is invalid: allowed int in "
     "[0, 1000]"),
    ("pd_pf_controller:\n  ros__parameters:\n    rt_priority: 99\n",
     "node 'pd_pf_controller': parameter 'rt_priority' = 99 is invalid: allowed int in "
     "[0, 98]"),
    ("metrics:\n  ros__parameters:\n    rt_priority: high\n",
     "node 'metrics': parameter 'rt_priority' = 'high' is invalid"),
]


@pytest.mark.parametrize("content, message", PARAMS_FILES,
                         ids=[f"file{i}" for i in range(len(PARAMS_FILES))])
def test_bad_params_file_is_one_line_naming_the_key_in_both_front_ends(tmp_path, content,
                                                                       message):
    f = tmp_path / "p.yaml"
    f.write_text(content)
    cli = one_error_line(hexapod("simulate", "--params", str(f)), "hexapod simulate")
    graph = one_error_line(run_graph("--params", str(f), "--bag", str(tmp_path / "b")),
                           "run_graph")
    assert message in cli
    assert cli == graph
    assert not (tmp_path / "b").exists() and not (tmp_path / "b_logs").exists()


OPTIONS = [  # (options, text the one line must hold); both front ends take them
    (["--t-max", "abc"], "argument --t-max: parameter 'actuator.t_max' = 'abc' is invalid: "
     "allowed float in (0, inf]"),
    (["--t-max=abc"], "argument --t-max: parameter 'actuator.t_max' = 'abc'"),
    (["--t-max", "nan"], "argument --t-max: parameter 'actuator.t_max' = nan"),
    (["--t-max=-5"], "argument --t-max: parameter 'actuator.t_max' = -5.0"),
    (["--ground-scale", "0"], "argument --ground-scale: parameter 'ground.scale' = 0.0"),
    (["--ground-scale=x1"], "argument --ground-scale: parameter 'ground.scale' = 'x1'"),
    (["--duration", "nan"], "argument --duration: parameter 'run.duration' = nan"),
    (["--duration", "1e7"], "argument --duration: parameter 'run.duration' = 10000000.0"),
    (["--duration=abc"], "argument --duration: parameter 'run.duration' = 'abc'"),
    (["--set", "ground.k_yy=3"], "parameter 'ground.k_yy' = 3 is invalid: allowed a known "
     "parameter name (did you mean 'ground.k_y'?)"),
    (["--set", "gait.duty_factor=1.5"], "parameter 'gait.duty_factor' = 1.5"),
    (["--set=actuator.t_max=1e-3x"], "parameter 'actuator.t_max' = '1e-3x'"),
    (["--control-rate", "0"], "argument --control-rate: '0' is not a control rate (Hz)"),
    (["--control-rate=abc"], "argument --control-rate: 'abc' is not a control rate (Hz)"),
    (["--control-rate", "1500"], "parameter 'sim.control_period' = "),
    (["--no-such-option"], "unrecognized arguments: --no-such-option"),
]


@pytest.mark.parametrize("options, message", OPTIONS,
                         ids=[" ".join(o) for o, _ in OPTIONS])
def test_bad_option_is_one_line_naming_it_in_both_front_ends(tmp_path, options, message):
    unknown = "unrecognized" in message  # argparse's top-level parser reports it
    cli = one_error_line(hexapod("simulate", *options),
                         "hexapod" if unknown else "hexapod simulate")
    graph = one_error_line(run_graph(*options, "--bag", str(tmp_path / "b")), "run_graph")
    assert message in cli
    assert message in graph
    if "unrecognized" not in message:
        assert cli == graph


GRAPH_ONLY = [
    (["--switch-at", "nan"], "argument --switch-at: 'nan' is not a simulated time"),
    (["--switch-at=-1"], "argument --switch-at: '-1' is not a simulated time"),
    (["--switch-at", "100"], "argument --switch-at: 100 s is after the end of the run"),
    (["--controller", "pd-x"], "argument --controller: 'pd-x' is not a controller name"),
    (["--no-builtin", "pd_x"], "argument --no-builtin: 'pd_x': expected a comma list of "
     "pd_p, pd_pf"),
    (["--no-builtin", "pd_pf"], "argument --controller: pd_pf is not started (--no-builtin "
     "pd_pf)"),
    (["--mode=fast"], "argument --mode: invalid choice: 'fast'"),
    (["--duration"], "argument --duration: expected one argument"),
    (["--rt-priority", "99"], "argument --rt-priority: '99' is not a SCHED_FIFO priority in "
     "[0, 98]"),
    (["--rt-priority=abc"], "argument --rt-priority: 'abc' is not a SCHED_FIFO priority"),
    (["--rt-priority", "1.5"], "argument --rt-priority: '1.5' is not a SCHED_FIFO priority "
     "(an integer in [0, 98])"),
    (["--ground-seed", "-1"], "argument --ground-seed: '-1' is not a seed"),
    (["--ground-seed", "1.5"], "argument --ground-seed: '1.5' is not a seed"),
    (["--ground-spread", "500"], "argument --ground-spread: '500' is not a spread in % "
     "(0 to 200)"),
    (["--ground-spread", "nan"], "argument --ground-spread: 'nan' is not a spread"),
]


@pytest.mark.parametrize("options, message", GRAPH_ONLY,
                         ids=[" ".join(o) for o, _ in GRAPH_ONLY])
def test_bad_graph_option_is_one_line(tmp_path, options, message):
    assert message in one_error_line(run_graph(*options, "--bag", str(tmp_path / "b")),
                                     "run_graph")


def test_the_script_passes_bad_settings_to_the_launcher(tmp_path):
    """scripts/run_graph.sh says what its launcher says, and starts nothing: one case of
    each kind above (a params file, an option of both front ends, a graph-only option)."""
    f = tmp_path / "p.yaml"
    f.write_text(PARAMS_FILES[1][0])
    for args, message in ((["--params", str(f)], PARAMS_FILES[1][1]), OPTIONS[0],
                          GRAPH_ONLY[3]):
        bag = tmp_path / "b"
        script = run_graph_script(*args, "--bag", str(bag))
        line = one_error_line(script, "run_graph")
        assert message in line
        assert line == one_error_line(run_graph(*args, "--bag", str(bag)), "run_graph")
        assert not bag.exists() and not (tmp_path / "b_logs").exists()


CLI_ONLY = [
    (["simulate", "--duration", "1e6"], "parameter 'run.duration' = 1000000.0 is invalid: "
     "allowed at most"),
    (["simulate", "--switch", "nan:pd_p"], "--switch expects TIME:CONTROLLER"),
    (["simulate", "--switch", "1:pd_x"],
     "--switch '1:pd_x': parameter 'run.controller' = 'pd_x' is invalid: allowed one of "
     "pd_alpha, pd_p, pd_pf"),
    (["sweep", "ground", "--range", "10:100"], "argument --range: '10:100' is not"),
    (["sweep", "ground", "--range", "10:100:0"], "argument --range: '10:100:0': N = 0"),
    (["sweep", "ground", "--range", ","], "argument --range: ',' is not"),
    (["sweep", "ground", "--range", "abc"], "argument --range: 'abc' is not"),
    (["sweep", "ground", "--range=10:5:3"], "argument --range: '10:5:3': HI = 5 is below"),
    (["sweep", "tmax", "--t-max-list", "400,x"], "argument --t-max-list: '400,x' is not"),
    (["switch", "pd_p", "--timeout=nan"], "argument --timeout: 'nan' is not a timeout (s)"),
    (["switch", "pd/x"], "argument controller: 'pd/x' is not a controller name"),
    (["status", "--timeout", "-1"], "argument --timeout: '-1' is not a timeout (s)"),
]


@pytest.mark.parametrize("args, message", CLI_ONLY, ids=[" ".join(a) for a, _ in CLI_ONLY])
def test_bad_cli_input_is_one_line(args, message):
    assert message in one_error_line(hexapod(*args), f"hexapod {args[0]}")


def test_yaml_numbers_are_numbers_in_the_cli(tmp_path):
    f = tmp_path / "p.yaml"
    f.write_text(BASE.replace("t_max: 400.0", "t_max: 1.5e2"))
    r = hexapod("simulate", "--params", str(f), "--controller", "pd_p", "--duration", "1")
    assert r.returncode == 0, r.stderr
    assert "T_max = 150 N m" in r.stdout


def test_one_default_scenario_in_every_front_end():
    """run_graph's lockstep default is the params file's scenario, which `hexapod simulate`
    and `hexapod reproduce` run: the same parameters, so (lockstep graph == engine, the
    graph tests) the same recorded motion. Realtime mode's own default (1 kHz, PD-P&F's
    force loop in the drive) is explicit and printed."""
    from hexapod_bringup.graph_launcher import build_parser, convergence_note, settings
    from hexapod_common.core.params import load_params

    parse = build_parser().parse_args
    p, _ = settings(parse(["--no-switch", "--duration", "3"]))
    assert p == load_params(**{"run.duration": 3.0})
    assert p.sim.control_period == 1e-4 and p.pd_pf.force_loop == "topic"
    rt, _ = settings(parse(["--mode", "realtime", "--duration", "3"]))
    assert rt.sim.control_period == 1e-3 and rt.pd_pf.force_loop == "drive"
    assert "force loop in the drive" in convergence_note(rt)
    own, _ = settings(parse(["--mode", "realtime", "--control-rate", "2000"]))
    assert own.sim.control_period == 5e-4 and own.pd_pf.force_loop == "topic"


def test_runs_started_in_the_same_second_get_bags_of_their_own(tmp_path):
    from hexapod_bringup.graph_launcher import fresh_bag_path

    first = fresh_bag_path(tmp_path / "bags", "20261205-120000")
    second = fresh_bag_path(tmp_path / "bags", "20261205-120000")
    (tmp_path / "bags" / "20261205-120000-3").mkdir()  # a bag there already (no logs)
    third = fresh_bag_path(tmp_path / "bags", "20261205-120000")
    assert [p.name for p in (first, second, third)] == [
        "20261205-120000", "20261205-120000-2", "20261205-120000-4"]
    assert all(Path(f"{p}_logs").is_dir() for p in (first, second, third))
