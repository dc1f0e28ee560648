"""`hexapod controllers` and the front doors that take any registered controller."""
import json
import subprocess
import sys

import pytest


def hexapod(*args, check=False, cwd=None):
    return subprocess.run([sys.executable, "-m", "hexapod_bringup.cli", *args],
                          capture_output=True, text=True, check=check, timeout=900, cwd=cwd)


def test_controllers_lists_names_parameters_defaults_and_ranges():
    out = hexapod("controllers", check=True).stdout
    for name in ("pd_p", "pd_pf", "pd_alpha"):
        assert any(line.startswith(name + " ") for line in out.splitlines()), name
    rows = {line.split()[0]: line for line in out.splitlines() if line.startswith("  pd_")}
    assert "float in (0, 2)" in rows["pd_alpha.alpha"]
    assert "default 1.0" in rows["pd_alpha.alpha"]
    assert "int in [1, 100000]" in rows["pd_alpha.memory"]
    assert "one of topic, drive" in rows["pd_pf.force_loop"]
    assert "default 0.9" in rows["pd_pf.kf"]
    doc = json.loads(hexapod("controllers", "--json", "--set", "pd_alpha.alpha=0.6",
                             check=True).stdout)
    alpha = [q for q in doc["pd_alpha"]["parameters"] if q["name"] == "pd_alpha.alpha"][0]
    assert alpha["default"] == 0.6
    assert doc["pd_p"]["compiled"] and not doc["pd_alpha"]["compiled"]


def test_unknown_controller_is_one_line_with_the_known_names():
    r = hexapod("simulate", "--controller", "pd_q")
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1
    assert "pd_alpha, pd_p, pd_pf" in lines[0]
    r = hexapod("sweep", "ground", "--controllers", "pd_p,nope", "--range", "100")
    assert r.returncode == 2 and "nope" in r.stderr and "pd_alpha" in r.stderr


@pytest.mark.parametrize("args", [
    ("--controller", "pd_alpha"),
    ("--controller", "pd_pf", "--set", "pd_pf.force_loop=drive", "--control-rate", "1000"),
])
def test_simulate_json_with_any_controller(args):
    extra = ["--set", "run.duration=2.0"]
    r = hexapod("simulate", *args, *extra, "--json")
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    (name,) = doc
    assert name == args[1]
    assert doc[name]["status"] == "ok"
    assert doc[name]["indices"]["E_av"] > 0


def test_sweep_and_tune_take_pd_alpha(tmp_path):
    r = hexapod("sweep", "ground", "--controllers", "pd_p,pd_pf,pd_alpha", "--range", "100",
                "--t-max-list", "400", "--set", "run.duration=2.0", "--set",
                "sim.control_period=0.0005", "--backend", "inline", "--no-progress",
                "--out", str(tmp_path / "sw"))
    assert r.returncode == 0, r.stderr
    rows = json.loads((tmp_path / "sw" / "sweep_ground_tmax400.json").read_text())
    assert sorted(row["controller"] for row in rows) == ["pd_alpha", "pd_p", "pd_pf"]
    r = hexapod("tune", "--controller", "pd_alpha", "--factors", "1", "--grid",
                "kd1=200,250", "--set", "run.duration=2.0", "--set",
                "sim.control_period=0.0005", "--backend", "inline", "--no-progress",
                "--json", str(tmp_path / "tune.json"))
    assert r.returncode == 0, r.stderr
    doc = json.loads((tmp_path / "tune.json").read_text())
    assert doc["controller"] == "pd_alpha"
    assert sorted(g["gains"]["kd1"] for g in doc["all"]) == [200.0, 250.0]
    # the printed score is the objective ranked on: the stationary hip errors
    assert r.stdout.count("trk_xH+eps_yH = ") == 2 and "eps_xH+eps_yH" not in r.stdout


USER_MODULE = '''
from dataclasses import dataclass
from hexapod_control.core.controller_api import param, torque_command


@dataclass(frozen=True)
class P:
    stiff: float = param("joint stiffness (N m/rad)", 0.0, 1e6, default=3.0e4)


class Stiff:
    """A PD law with a fixed damping, written by a user."""
    name = "stiff"
    Params = P

    def __init__(self, params, context):
        self.k = params.stiff

    def reset(self):
        pass

    def law(self, obs):
        return torque_command(self.k * (obs.theta_d - obs.theta)
                              + 300.0 * (obs.theta_vel_d - obs.theta_vel))
'''


def test_module_class_path_in_controllers_and_simulate(tmp_path):
    (tmp_path / "cli_ctl_mod.py").write_text(USER_MODULE)
    out = hexapod("controllers", "--load", "cli_ctl_mod:Stiff", check=True,
                  cwd=tmp_path).stdout
    row = [line for line in out.splitlines() if line.strip().startswith("stiff.stiff")]
    assert len(row) == 1 and "default 30000.0" in row[0] and "float in [0, 1e+06]" in row[0]
    r = hexapod("simulate", "--controller", "cli_ctl_mod:Stiff", "--set", "stiff.stiff=1e5",
                "--set", "run.duration=2.0", "--control-rate", "2000", "--json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc["cli_ctl_mod:Stiff"]["status"] == "ok"
    r = hexapod("simulate", "--controller", "cli_ctl_mod:Stiff", "--set", "stiff.stiff=-1",
                cwd=tmp_path)
    assert r.returncode == 2 and "stiff.stiff" in r.stderr and "[0, 1e+06]" in r.stderr
