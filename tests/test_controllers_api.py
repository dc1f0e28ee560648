"""The controller API: registry (entry points, module:Class), parameters from each
controller's spec table, the per-tick plug-in loop and the drive-placed force loop."""
import math
import textwrap

import numpy as np
import pytest

from hexapod_common.core.errors import ParameterError
from hexapod_common.core.params import load_params, read_params_file, registered_controllers
from hexapod_control.core import registry
from hexapod_control.core.builtin import PdP, PdPf
from hexapod_control.core.closed_loop import Case, batch_code, run, run_plugin_ticks
from hexapod_control.core.controllers import PD_P, PD_PF, PD_PF_DRIVE
from hexapod_bringup.core.simulate import evaluate_batch, simulate
from hexapod_metrics.core.indices import INDEX_NAMES
from hexapod_common.core.layout import model_vector
from hexapod_sim.core.engine import initial_state


def test_builtins_are_registered_by_entry_point():
    eps = registered_controllers()
    assert {"pd_p", "pd_pf", "pd_alpha"} <= set(eps)
    assert eps["pd_p"].load() is PdP and eps["pd_pf"].load() is PdPf
    assert {"pd_p", "pd_pf", "pd_alpha"} <= set(registry.names())


def test_unknown_controller_is_one_line_listing_the_known():
    with pytest.raises(ParameterError) as err:
        registry.load("pd_q")
    text = str(err.value)
    assert "\n" not in text
    for name in registry.names():
        assert name in text
    with pytest.raises(ParameterError, match="run.controller.*one of pd_alpha, pd_p, pd_pf"):
        load_params(**{"run.controller": "pid"})
    with pytest.raises(ParameterError, match="importable module:Class"):
        registry.load("no_such_module_xyz:Thing")


@pytest.fixture
def user_module(tmp_path, monkeypatch):
    """A user's controller in a module of its own, loaded by module:Class path."""
    (tmp_path / "my_ctl_mod.py").write_text(textwrap.dedent('''
        from dataclasses import dataclass
        import numpy as np
        from hexapod_control.core.controller_api import param, torque_command

        @dataclass(frozen=True)
        class P:
            gain: float = param("joint stiffness (N m/rad)", 0.0, 1e6, default=5.0e4)
            damping: float = param("joint damping (N m s/rad)", 0.0, 1e6, default=200.0)

        class NoLaw:
            Params = P

            def reset(self):
                pass

        class MyCtl:
            """A plain PD written by a user."""
            name = "my_ctl"
            Params = P

            def __init__(self, params, context):
                self.p = params
                self.ticks = 0

            def reset(self):
                self.ticks = 0

            def law(self, obs):
                self.ticks += 1
                return torque_command(self.p.gain * (obs.theta_d - obs.theta)
                                      + self.p.damping * (obs.theta_vel_d - obs.theta_vel))
        '''))
    from hexapod_common.core.params import controller_names, unregister_controller_group

    before = set(controller_names())
    monkeypatch.syspath_prepend(str(tmp_path))
    yield "my_ctl_mod:MyCtl"
    # groups are process-wide: a later load_params would carry them to worker processes
    # that cannot import this test's module
    for name in set(controller_names()) - before:
        unregister_controller_group(name)


def test_drive_command_broadcasts_and_names_a_bad_field():
    from hexapod_control.core.controller_api import DriveCommand, torque_command

    t = np.arange(12.0).reshape(6, 2)
    c = DriveCommand(0.5, np.array([1.0, 2.0]), np.full((6, 1), 3.0), 0.0, t, 0.0).stacked()
    assert c.shape == (6, 6, 2)
    assert np.all(c[0] == 0.5) and np.all(c[1][:, 1] == 2.0) and np.all(c[2] == 3.0)
    np.testing.assert_array_equal(c[4], t)
    np.testing.assert_array_equal(torque_command(t).stacked()[4], t)
    assert not torque_command(t).stacked()[[0, 1, 2, 3, 5]].any()
    with pytest.raises(ValueError, match=r"field dq_ref: shape \(3,\)"):
        DriveCommand(0.0, np.zeros(3), 0.0, 0.0, 0.0, 0.0).stacked()


def test_module_class_path_runs_with_its_own_parameters(user_module):
    cls = registry.load(user_module)
    assert cls.__name__ == "MyCtl"
    p = load_params()
    assert p.gains(user_module).gain == 5.0e4  # the spec table's default
    q = p.with_values(**{"my_ctl.gain": 6.0e4})
    assert q.gains(user_module).gain == 6.0e4
    with pytest.raises(ParameterError, match=r"my_ctl.damping.*float in \[0, 1e\+06\]"):
        p.with_values(**{"my_ctl.damping": -1.0})
    r = run(q, user_module, 0.05)
    assert r.diverged_at is None and np.all(np.isfinite(r.obs))
    with pytest.raises(ParameterError, match=r"NoLaw lacks law\(\)"):
        registry.load("my_ctl_mod:NoLaw")
    assert not np.array_equal(r.obs, run(p, user_module, 0.05).obs)


@pytest.mark.parametrize("name, value, allowed", [
    ("pd_alpha.alpha", 2.0, r"float in \(0, 2\)"),
    ("pd_alpha.alpha", 0.0, r"float in \(0, 2\)"),
    ("pd_alpha.memory", 0, r"int in \[1, 100000\]"),
    ("pd_alpha.memory", 2.5, r"int in \[1, 100000\]"),
    ("pd_alpha.kd1", -1.0, r"float in \[0, 1e\+09\]"),
    ("pd_pf.force_loop", "bus", "one of topic, drive"),
])
def test_controller_parameter_ranges(name, value, allowed):
    with pytest.raises(ParameterError, match=rf"parameter '{name}' = .* allowed {allowed}"):
        load_params(**{name: value})


def test_controller_groups_from_params_files_and_overrides(tmp_path):
    p = load_params(**{"pd_alpha.alpha": 0.8})
    assert p.pd_alpha.alpha == 0.8
    assert p.pd_p.kp1 == read_params_file(_shipped())["pd_p.kp1"]
    assert p.pd_pf.force_loop == "topic"
    assert p.to_flat()["pd_alpha.memory"] == p.pd_alpha.memory
    # a params file written before force_loop existed still loads (its spec default)
    text = _shipped().read_text().replace("      force_loop: topic", "")
    assert "force_loop" not in text
    f = tmp_path / "old.yaml"
    f.write_text(text)
    assert load_params(f).pd_pf.force_loop == "topic"


def _shipped():
    from hexapod_common.core.params import default_params_path

    return default_params_path()


def test_plugin_loop_with_a_builtin_is_bit_identical_to_the_compiled_path():
    """PD-P and PD-P&F (topic) through the per-tick Python loop and the drive (torque-only
    commands) reproduce the compiled run_ticks path exactly."""
    for controller in ("pd_p", "pd_pf"):
        p = load_params(**{"sim.control_period": 5e-4})  # 10 substeps per tick
        n = 300
        fast = run(p, controller, n * p.sim.control_period)
        s, torque = initial_state(p), np.zeros((6, 2))
        obs, cmd = np.full_like(fast.obs[:n], np.nan), np.full_like(fast.command, np.nan)
        done = run_plugin_ticks(s, model_vector(p), registry.create(controller, p),
                                fast.reference.theta[:n], fast.reference.theta_vel[:n], torque,
                                p.substeps, 0.0, p.sim.control_period, obs, cmd)
        assert done == n
        np.testing.assert_array_equal(obs, fast.obs[:n])
        np.testing.assert_array_equal(cmd, fast.command)


def test_pd_pf_drive_law_through_the_plugin_loop_equals_the_compiled_drive_loop():
    """builtin.PdPf.law in drive mode (the Python law, per tick) and run_drive_ticks (what
    run() uses for it) give the same numbers bit for bit."""
    p = load_params(**{"sim.control_period": 5e-4, "pd_pf.force_loop": "drive"})
    n = 300
    fast = run(p, "pd_pf", n * p.sim.control_period)
    s, torque = initial_state(p), np.zeros((6, 2))
    obs, cmd = np.full_like(fast.obs[:n], np.nan), np.full_like(fast.command, np.nan)
    ctrl = registry.create("pd_pf", p)
    assert not ctrl.torque_only
    done = run_plugin_ticks(s, model_vector(p), ctrl, fast.reference.theta[:n],
                            fast.reference.theta_vel[:n], torque, p.substeps, 0.0,
                            p.sim.control_period, obs, cmd)
    assert done == n
    np.testing.assert_array_equal(obs, fast.obs[:n])
    np.testing.assert_array_equal(cmd, fast.command)


def test_drive_force_loop_at_every_physics_step_equals_the_topic_law():
    """With control at every physics step, PD-P&F's force loop in the drive computes the
    topic law (the drive's foot force is the tick's observed one) up to rounding."""
    p = load_params(**{"sim.control_period": load_params().sim.dt})
    topic = run(p, "pd_pf", 0.3)
    drive = run(p.with_values(**{"pd_pf.force_loop": "drive"}), "pd_pf", 0.3)
    assert drive.diverged_at is None
    np.testing.assert_allclose(drive.obs, topic.obs, rtol=0, atol=1e-7 * np.abs(topic.obs).max())


def test_drive_mode_pd_pf_at_1khz_runs_finite_and_differs_from_topic():
    p = load_params(**{"sim.control_period": 1e-3, "pd_pf.force_loop": "drive"})
    sim = simulate(p, "pd_pf", 2.0)
    assert sim.outcome.status == "ok"
    for name in INDEX_NAMES:
        assert math.isfinite(getattr(sim.indices, name))
    topic = simulate(p.with_values(**{"pd_pf.force_loop": "topic"}), "pd_pf", 2.0).indices
    assert topic is not None and topic.eps_xH != sim.indices.eps_xH


def test_batch_with_plugins_and_drive_equals_one_by_one():
    """PD-P&F in the drive runs in the compiled batch (its own code), a plug-in one by one;
    every case gets its single run's indices."""
    p = load_params(**{"sim.control_period": 5e-4})
    drive = p.with_values(**{"pd_pf.force_loop": "drive"})
    cases = [Case(p, "pd_p"), Case(drive, "pd_pf"), Case(p, "pd_alpha"), Case(p, "pd_pf"),
             Case(drive.with_values(**{"ground.scale": 3.0, "actuator.t_max": 170.0}),
                  "pd_pf"),
             Case(drive.with_values(**{"sim.dt": drive.sim.dt / 2}), "pd_pf")]
    assert [batch_code(c) for c in cases] == [PD_P, PD_PF_DRIVE, None, PD_PF, PD_PF_DRIVE,
                                              PD_PF_DRIVE]
    batch = evaluate_batch(cases, 2.0)
    for c, b in zip(cases, batch):
        one = simulate(c.params, c.controller, 2.0)
        assert b.status == one.outcome.status == "ok"
        for name in INDEX_NAMES:
            assert getattr(b.indices, name) == pytest.approx(getattr(one.indices, name),
                                                             rel=1e-12, abs=1e-15), name


def test_switching_between_compiled_and_plugin_controllers():
    p = load_params(**{"sim.control_period": 5e-4})
    r = run(p, "pd_p", 1.0, switches=[(0.3, "pd_alpha"), (0.6, "pd_p")])
    assert r.diverged_at is None
    assert [c for _, c in r.switches] == ["pd_p", "pd_alpha", "pd_p"]
    plain = run(p, "pd_p", 1.0)
    k = int(round(0.3 / p.sim.control_period))
    np.testing.assert_array_equal(r.obs[:k + 1], plain.obs[:k + 1])


def test_a_parameters_kind_is_its_annotation_without_kind_named():
    """`warmup: int = param(...)` refuses 2.5 with no kind=int written; a float parameter
    whose default is written as an integer still takes 2.5; a default that does not fit its
    kind is refused when the controller is registered."""
    from dataclasses import dataclass

    from hexapod_common.core.params import (check_value, register_controller_group,
                                            unregister_controller_group)
    from hexapod_control.core.controller_api import param

    @dataclass(frozen=True)
    class Kinds:
        kp: float = param("stiffness (N m/rad)", 0.0, 1e9, default=20000)
        warmup: int = param("ticks before the law acts", 0, 100, default=3)
        on: bool = param("switch", default=True)
        mode: str = param("mode", default="a", choices=("a", "b"))

    register_controller_group("kinds_test", Kinds)
    try:
        assert check_value("kinds_test.kp", 2.5e4 + 0.5) == 25000.5
        with pytest.raises(ParameterError, match=r"'kinds_test.warmup' = 2.5 is invalid: "
                                                 r"allowed int in \[0, 100\]"):
            check_value("kinds_test.warmup", 2.5)
        assert check_value("kinds_test.warmup", 4) == 4
        with pytest.raises(ParameterError, match="a string, where a boolean is expected"):
            check_value("kinds_test.on", "yes")
        with pytest.raises(ParameterError, match="kinds_test.mode"):
            check_value("kinds_test.mode", "c")
    finally:
        unregister_controller_group("kinds_test")

    @dataclass(frozen=True)
    class Bad:
        warmup: int = param("ticks", 0, 100, default=2.5)

    with pytest.raises(TypeError, match="controller 'bad_test': the default of parameter "
                                        "'warmup' does not fit it"):
        register_controller_group("bad_test", Bad)
    unregister_controller_group("bad_test")
