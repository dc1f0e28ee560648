"""`hexapod simulate`: indices on stdout, JSON, one-line errors with a non-zero exit."""
import json
import subprocess
import sys
from pathlib import Path

import pytest

SCRIPTS = Path(__file__).resolve().parents[1] / "scripts"


def run_script(name, *args, cwd=None):
    """scripts/<name> with ``args`` in this interpreter: the finished process."""
    return subprocess.run([sys.executable, str(SCRIPTS / name), *args], capture_output=True,
                          text=True, timeout=120, cwd=cwd)


def test_simulate_prints_the_seven_indices(hexapod):
    r = hexapod("simulate", "--controller", "pd_pf")
    assert r.returncode == 0, r.stderr
    out = r.stdout
    for name in ("E_av", "T_L", "F_L", "eps_xH", "eps_yH", "eps_xF", "eps_yF"):
        assert name in out
    assert "T_max = 400 N m" in out


def test_simulate_json_matches_the_python_api(hexapod):
    from hexapod_bringup.core.simulate import simulate
    from hexapod_common.core.params import load_params

    r = hexapod("simulate", "--controller", "both", "--t-max", "150", "--json")
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    p = load_params(**{"actuator.t_max": 150.0})
    for c in ("pd_p", "pd_pf"):
        assert doc[c]["status"] == "ok"
        sim = simulate(p, c)
        assert doc[c]["indices"]["eps_xH"] == pytest.approx(sim.indices.eps_xH, rel=1e-12)
        # every full gait cycle, the last one being the window (run.eval_cycles = 1)
        cycles = doc[c]["cycles"]
        assert [k["cycle"] for k in cycles] == [0, 1, 2]
        assert cycles[-1]["eps_xF"] == doc[c]["indices"]["eps_xF"]
        for k, i in zip(cycles, sim.outcome.cycles):
            assert k["drift_xH"] == pytest.approx(i.drift_xH, rel=1e-12)
            assert k["trk_xF"] == pytest.approx(i.trk_xF, rel=1e-12)


@pytest.mark.parametrize("args, message", [
    (["--t-max", "-5"], "parameter 'actuator.t_max' = -5.0 is invalid: allowed float in (0, inf]"),
    (["--set", "gait.duty_factor=1.5"], "parameter 'gait.duty_factor' = 1.5"),
    (["--params", "/nonexistent.yaml"], "cannot read params file"),
])
def test_bad_input_is_one_line_and_nonzero(hexapod, args, message):
    r = hexapod("simulate", *args)
    assert r.returncode == 2
    assert message in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr


@pytest.mark.parametrize("at, where", [("2.5", "inside the window: the indices mix both"),
                                       ("1.5", "before the window: the indices are the new")])
def test_simulate_says_where_a_live_change_falls_against_the_indices_window(hexapod, at,
                                                                            where):
    r = hexapod("simulate", "--controller", "pd_p", "--duration", "3", "--set",
                "sim.control_period=0.001", "--change", f"{at}:ground.scale=2.0")
    assert r.returncode == 0, r.stderr
    assert "window = [2, 3] s" in r.stdout
    assert f"parameter change: ground.scale = 2.0 at {at} s ({where}" in r.stdout


@pytest.mark.parametrize("args, code, message", [
    (["--runs", "0"], 2, "argument --runs: expected a whole number >= 1"),
    (["--range", "10:x:3"], 2, "argument --range: '10:x:3' is not"),
    (["--t-max-list", "-5"], 2, "argument --t-max-list: '-5' is not T_max"),
    (["--range", "0,100", "--runs", "1"], 1,
     "the batched engine's run failed (exit 1): hexapod_common.core.errors.ParameterError: "
     "parameter 'ground.scale' = 0.0 is invalid"),
])
def test_bench_sweep_refuses_bad_options_in_one_line(args, code, message):
    """scripts/bench_sweep.py: a bad option, or a sweep the engine refuses, is one line and
    a non-zero exit before any figure is printed."""
    out = run_script("bench_sweep.py", *args)
    assert out.returncode == code
    lines = out.stderr.strip().splitlines()
    assert message in lines[-1] and "Traceback" not in out.stderr
    assert "medians" not in out.stdout


@pytest.mark.parametrize("args, code, message", [
    (["--duration", "-1"], 1, "the lockstep run left no indices.json (exit 2): run_graph: "
     "error: argument --duration: parameter 'run.duration' = -1.0 is invalid"),
    (["--duration", "nan"], 1, "parameter 'run.duration' = nan is invalid"),
    (["--controller", "pd_x"], 2, "argument --controller: invalid choice: 'pd_x'"),
    (["--set", "ground.scale=-2"], 1, "parameter 'ground.scale' = -2"),
    (["--set", "no_such.thing=1"], 1, "no_such.thing"),
])
def test_realtime_vs_lockstep_refuses_bad_options_in_one_line(args, code, message, tmp_path):
    """scripts/realtime_vs_lockstep.py: a bad option, or one its graph runs refuse, is one
    line and a non-zero exit before any run starts its graph."""
    out = run_script("realtime_vs_lockstep.py", *args, cwd=tmp_path)
    assert out.returncode == code, out.stderr
    lines = out.stderr.strip().splitlines()
    assert message in lines[-1] and "Traceback" not in out.stderr
    assert out.stdout == ""
