"""A user's controller plug-in as a package (docs/controllers.md, "Engine plug-ins"): made
here, installed with the documented command, run on the graph by its registered name; its
law reads the hip rows of the observation, and the lockstep graph run equals `hexapod
simulate` tick for tick; the bag analyses where the plug-in is not installed."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from hexapod_common.core import topics as T
from hexapod_metrics.bag import open_bag, read_joint_state_arrays

from .test_graph_exits import ROOT, Script

SETUP = '''
from setuptools import setup

setup(name="hip_law", version="0.1", packages=["hip_law"],
      entry_points={"hexapod.controllers": ["hip_pd = hip_law.law:HipPd"]})
'''

#: A joint PD that damps each leg's hip (the body segment) by its vertical velocity: it reads
#: the hip rows of the observation (NaN there would make every command NaN, dropped).
LAW = '''
from dataclasses import dataclass

from hexapod_common.core.layout import O_HV
from hexapod_control.core.controller_api import param, torque_command


@dataclass(frozen=True)
class Params:
    kp: float = param("joint stiffness (N m/rad)", 0.0, 1e9, default=100000)
    kd: float = param("joint damping (N m s/rad)", 0.0, 1e9, default=250.0)
    k_hip: float = param("hip damping (N m s/m)", 0.0, 1e6, default=50.0)
    warmup: int = param("ticks before the hip term acts", 0, 1000, default=3)


class HipPd:
    name = "hip_pd"
    Params = Params

    def __init__(self, params, context):
        self.p = params
        self.k = 0

    def reset(self):
        self.k = 0

    def law(self, obs):
        p = self.p
        self.k += 1
        hip = obs.raw[O_HV][:, 1:2] if self.k > p.warmup else 0.0
        return torque_command(p.kp * (obs.theta_d - obs.theta)
                              + p.kd * (obs.theta_vel_d - obs.theta_vel) - p.k_hip * hip)
'''


def _cli(*args: str, env: dict[str, str]) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "hexapod_bringup.cli", *args], env=env,
                          capture_output=True, text=True, timeout=600)


def test_a_users_plugin_package_installs_runs_on_the_graph_and_equals_the_engine(
        tmp_path, monkeypatch):
    pkg = tmp_path / "hip_law"
    (pkg / "hip_law").mkdir(parents=True)
    (pkg / "setup.py").write_text(SETUP)
    (pkg / "hip_law" / "__init__.py").write_text("")
    (pkg / "hip_law" / "law.py").write_text(LAW)
    # The documented command (a wheel built with the venv's setuptools and wheel, no
    # download); --target keeps it out of the venv the other tests share.
    site = tmp_path / "site"
    r = subprocess.run([str(ROOT / "scripts" / "install_controller.sh"), str(pkg),
                        "--target", str(site)], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    base_path = os.environ.get("PYTHONPATH", "")
    with_plugin = {**os.environ, "PYTHONPATH": f"{site}{os.pathsep}{base_path}"}
    monkeypatch.setenv("PYTHONPATH", with_plugin["PYTHONPATH"])  # run_graph.sh's too

    listed = _cli("controllers", env=with_plugin)
    assert listed.returncode == 0 and "hip_pd.warmup" in listed.stdout, listed.stderr
    # an int parameter (by its annotation, no kind=int named) refuses 2.5, in one line
    r = _cli("simulate", "--controller", "hip_pd", "--set", "hip_pd.warmup=2.5",
             env=with_plugin)
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert "'hip_pd.warmup' = 2.5 is invalid: allowed int in [0, 1000]" in r.stderr

    # on the graph, in charge from tick 0 (the launcher starts its node by name)
    s = Script(tmp_path, "--controller", "hip_pd", "--no-switch", "--duration", "1")
    try:
        assert s.wait(600) == 0, s.stderr()
    finally:
        s.kill_all()
    engine = tmp_path / "engine_bag"
    r = _cli("simulate", "--controller", "hip_pd", "--duration", "1", "--set",
             "sim.dt=0.0001", "--control-rate", "1000", "--bag", str(engine), env=with_plugin)
    assert r.returncode == 0, r.stderr

    def arrays(bag: Path) -> dict[str, np.ndarray]:
        with open_bag(bag) as b:
            out = {}
            for topic in (*T.STATE_TOPICS, T.JOINT_COMMANDS):
                a = read_joint_state_arrays(b, topic)
                out[topic] = np.stack([a.position, a.velocity, a.effort])
            return out
    graph, ref = arrays(s.bag), arrays(engine)
    for topic in ref:
        n = min(graph[topic].shape[1], ref[topic].shape[1])
        assert n >= 999, (topic, graph[topic].shape, ref[topic].shape)
        np.testing.assert_array_equal(graph[topic][:, :n], ref[topic][:, :n], err_msg=topic)
    assert np.isfinite(graph[T.JOINT_COMMANDS]).all()

    # analysed where the plug-in is not installed: its recorded parameters as recorded
    r = _cli("analyze", str(s.bag), "--no-plots", env={**with_plugin, "PYTHONPATH": base_path})
    assert r.returncode == 0, r.stderr
    assert ("parameters of controllers not registered here, taken as recorded (unchecked): "
            "hip_pd.k_hip=50.0, hip_pd.kd=250.0, hip_pd.kp=100000.0, hip_pd.warmup=3") \
        in r.stdout, r.stdout
    assert "hip_pd" in r.stdout.split("segment")[-1]


def test_a_module_class_path_on_the_graph_says_how_to_register(tmp_path):
    s = Script(tmp_path, "--controller", "my_law:MyPid")
    assert s.wait(120) == 2
    lines = s.stderr().strip().splitlines()
    assert len(lines) == 1 and "'my_law:MyPid' is a module:Class path" in lines[0], lines
    assert "entry_points={'hexapod.controllers': ['NAME = my_law:MyPid']}" in lines[0]
    assert "scripts/install_controller.sh PATH" in lines[0]
