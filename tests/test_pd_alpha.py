"""PD^alpha (Grünwald-Letnikov): weights, the public-API-only plug-in, and alpha = 1 = PD-P."""
import ast
import inspect

import numpy as np
import pytest

from hexapod_bringup.core.simulate import simulate
from hexapod_common.core.params import load_params
from hexapod_control.core import pd_alpha
from hexapod_control.core.pd_alpha import gl_weights


def test_grunwald_letnikov_weights():
    np.testing.assert_array_equal(gl_weights(1.0, 4), [1.0, -1.0, 0.0, 0.0, 0.0])
    np.testing.assert_allclose(gl_weights(2.0, 3), [1.0, -2.0, 1.0, 0.0], atol=1e-15)
    # binomial series (-1)^k C(0.5, k): 1, -1/2, -1/8, -1/16, -5/128
    np.testing.assert_allclose(gl_weights(0.5, 4), [1.0, -0.5, -0.125, -0.0625, -5 / 128])


def test_written_against_the_public_api_only():
    """The plug-in imports nothing of the project but the controller API."""
    tree = ast.parse(inspect.getsource(pd_alpha))
    project = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            mod = ("." * node.level) + (node.module or "")
            if node.level or mod.startswith("hexapod"):
                project.add(mod)
        elif isinstance(node, ast.Import):
            project |= {a.name for a in node.names if a.name.startswith("hexapod")}
    assert project == {".controller_api"}


def test_alpha_one_with_pd_p_gains_matches_pd_p_within_one_percent():
    """At the shipped (dt-converged) control rate, alpha = 1 (the backward difference of the
    error) with PD-P's gains gives PD-P's E_av, T_L and eps_xH within 1 %."""
    p = load_params()
    g = p.pd_p
    assert g.kf == 1.0
    q = p.with_values(**{"pd_alpha.alpha": 1.0, "pd_alpha.kp1": g.kp1, "pd_alpha.kd1": g.kd1,
                         "pd_alpha.kp2": g.kp2, "pd_alpha.kd2": g.kd2})
    ref = simulate(q, "pd_p").indices
    got = simulate(q, "pd_alpha").indices
    assert ref is not None and got is not None
    for name in ("E_av", "T_L", "eps_xH"):
        a, b = getattr(got, name), getattr(ref, name)
        assert abs(a - b) <= 0.01 * abs(b), f"{name}: pd_alpha {a:.6g} vs pd_p {b:.6g}"


@pytest.mark.parametrize("alpha", [0.7, 1.3])
def test_fractional_order_changes_the_walk(alpha):
    p = load_params(**{"sim.control_period": 5e-4, "pd_alpha.alpha": alpha,
                       "pd_alpha.memory": 50})
    one = simulate(p.with_values(**{"pd_alpha.alpha": 1.0}), "pd_alpha", 2.0)
    frac = simulate(p, "pd_alpha", 2.0)
    assert one.outcome.status == frac.outcome.status == "ok"
    assert not np.array_equal(frac.run.command[:200], one.run.command[:200])


def test_live_change_of_alpha_takes_effect_at_its_tick():
    p = load_params(**{"sim.control_period": 5e-4, "pd_alpha.memory": 50})
    plain = simulate(p, "pd_alpha", 2.0).run
    changed = simulate(p, "pd_alpha", 2.0, param_changes=[(1.0, {"pd_alpha.alpha": 0.8})]).run
    k = int(round(1.0 / p.sim.control_period))
    np.testing.assert_array_equal(changed.obs[:k + 1], plain.obs[:k + 1])
    assert not np.array_equal(changed.command[k], plain.command[k])
