"""Parameter validation: every error names the parameter, the value and the allowed range."""
import math

import pytest

from hexapod_common.core.errors import ParameterError, ParamsFileError
from hexapod_common.core.params import SPECS, load_params


def test_defaults_are_the_paper_base_experiment():
    p = load_params()
    assert (p.gait.duty_factor, p.gait.step_length, p.gait.body_height) == (0.5, 1.0, 1.8)
    assert (p.robot.body_mass, p.ground.k_y, p.actuator.t_max) == (87.4, 1e6, 400.0)
    assert p.pd_pf.as_tuple() == (20500.0, 110.0, 22000.0, 150.0, 0.9)
    # the paper experiments' resolution (E6): 5e-5 s physics, 10 kHz control
    assert (p.sim.dt, p.sim.control_period) == (5e-5, 1e-4)
    assert p.substeps == 2 and p.cycle_time == 1.0


@pytest.mark.parametrize("name, value, allowed", [
    ("ground.k_y", -1.0, r"float in \[0, 1e\+12\]"),
    ("gait.duty_factor", 1.0, r"float in \(0, 1\)"),
    ("gait.duty_factor", 0.0, r"float in \(0, 1\)"),
    ("actuator.t_max", 0.0, r"float in \(0, inf\]"),
    ("actuator.t_max", -5.0, r"float in \(0, inf\]"),
    ("run.controller", "pid", "one of pd_alpha, pd_p, pd_pf"),
    ("body.k_x", "stiff", "float"),
    ("run.eval_cycles", 1.5, "int"),
    ("sim.dt", True, "float"),
    ("ground.scale", math.nan, "float"),
])
def test_bad_value_names_parameter_and_range(name, value, allowed):
    with pytest.raises(ParameterError, match=rf"parameter '{name}' = .* allowed {allowed}"):
        load_params(**{name: value})


def test_infinite_t_max_is_expressible():
    assert math.isinf(load_params(**{"actuator.t_max": math.inf}).actuator.t_max)


def test_unreachable_gait_is_rejected():
    with pytest.raises(ParameterError, match="gait.body_height.*unreachable gait"):
        load_params(**{"gait.body_height": 1.99})
    with pytest.raises(ParameterError, match="unreachable gait"):
        load_params(**{"gait.step_length": 4.0, "gait.velocity": 4.0})


def test_control_period_must_be_multiple_of_dt():
    with pytest.raises(ParameterError, match="sim.control_period.*integer multiple of sim.dt"):
        load_params(**{"sim.control_period": 0.000125})


def test_unknown_parameter_is_rejected():
    with pytest.raises(ParameterError, match="parameter 'ground.kz'.*known parameter name"):
        load_params(**{"ground.kz": 1.0})


def test_with_values_validates():
    p = load_params()
    assert p.with_values(**{"ground.scale": 2.0}).ground.scale == 2.0
    with pytest.raises(ParameterError, match="ground.scale"):
        p.with_values(**{"ground.scale": -2.0})


def test_params_file_errors(tmp_path):
    with pytest.raises(ParamsFileError, match="cannot read"):
        load_params(tmp_path / "missing.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("robot: [1, 2\n")
    with pytest.raises(ParamsFileError, match="not valid YAML"):
        load_params(bad)
    flat = tmp_path / "flat.yaml"
    flat.write_text("ground:\n  k_y: 1.0\n")
    with pytest.raises(ParamsFileError, match="ros__parameters"):
        load_params(flat)


def test_missing_parameter_in_file_is_named(tmp_path):
    f = tmp_path / "p.yaml"
    f.write_text("/**:\n  ros__parameters:\n    ground:\n      k_y: 1.0\n")
    with pytest.raises(ParameterError, match="parameter 'robot.leg_length_1'"):
        load_params(f)


def test_every_spec_has_description_and_roundtrips():
    p = load_params()
    flat = p.to_flat()
    assert set(flat) == set(SPECS)
    assert all(s.description for s in SPECS.values())
