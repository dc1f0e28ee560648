"""CMA-ES tuning (E5's objective): finds a planted optimum, is reproducible and
backend-independent, scores its best set like an independent run, refuses bad options."""
import math
import subprocess
import sys

import numpy as np
import pytest

from hexapod_bringup.core.cmaes import REJECTED_SCORE, cmaes_search, tune_cmaes
from hexapod_bringup.core.experiments import hip_score, walking
from hexapod_bringup.core.parallel import InlineBackend, ProcessBackend
from hexapod_bringup.core.simulate import simulate
from hexapod_common.core.params import load_params

PLANTED = np.array([0.7, -1.2, 0.3, 1.9])


def _bowl(points):
    """A planted optimum at PLANTED (value 0.01 there), rejected (plateau) far from it."""
    out = []
    for x in points:
        d2 = float(np.sum((np.asarray(x) - PLANTED) ** 2 * [1.0, 4.0, 0.5, 2.0]))
        out.append(0.01 + d2 if d2 < 20.0 else REJECTED_SCORE)
    return out


def test_cmaes_finds_a_planted_optimum_within_its_budget():
    calls = []
    res = cmaes_search(_bowl, np.zeros(4), 0.5, 400, (math.log(0.05), math.log(20.0)),
                       seed=3, progress=calls.append)
    assert res.evaluations <= 400 and sum(calls) == res.evaluations
    assert np.allclose(res.best_x, PLANTED, atol=0.02)
    assert res.best_f == pytest.approx(0.01, abs=1e-3)
    again = cmaes_search(_bowl, np.zeros(4), 0.5, 400, (math.log(0.05), math.log(20.0)),
                         seed=3)
    assert again.fs == res.fs  # same seed, same search


def test_cmaes_budget_smaller_than_a_generation_is_refused():
    with pytest.raises(ValueError, match="less than one generation"):
        cmaes_search(_bowl, np.zeros(4), 0.5, 5, (-3.0, 3.0))


def test_cmaes_tuner_is_reproducible_backend_independent_and_scores_like_a_run():
    p = load_params()
    kw = dict(names=("kp1", "kd2"), budget=18, sigma0=0.4, seed=2, popsize=6,
              duration=2.0)
    inline = tune_cmaes(p, "pd_pf", backend=InlineBackend(), **kw)
    with ProcessBackend(2) as pool:
        procs = tune_cmaes(p, "pd_pf", backend=pool, **kw)
    assert inline.search.fs == procs.search.fs and inline.best == procs.best
    assert inline.evaluations == 18 and inline.search.generations == 3
    q = p.with_values(**{f"pd_pf.{k}": v for k, v in inline.best.items()})
    one = simulate(q, "pd_pf", 2.0)
    assert walking(one.outcome, p)
    assert hip_score(one.outcome) == pytest.approx(inline.best_score, rel=1e-9)
    assert inline.best_score <= min(inline.search.fs[:6])
    assert math.isfinite(inline.reference_score)


@pytest.mark.parametrize("args, words", [
    (["--budget", "0"], "--budget: 0"), (["--gains", "kp1,kx"], "'kx'"),
    (["--sigma0", "-1"], "--sigma0: -1"), (["--seed", "-4"], "--seed: -4"),
    (["--budget", "3"], "less than one generation"),
    (["--gains", "kp1,alpha"], "'alpha' is not a gain of pd_pf")])
def test_hostile_cmaes_options_are_one_line(args, words):
    out = subprocess.run([sys.executable, "-m", "hexapod_bringup.cli", "tune", "--controller",
                          "pd_pf", "--method", "cmaes", "--backend", "inline", *args],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 2 and out.stdout == ""
    assert len(out.stderr.strip().splitlines()) == 1 and words in out.stderr


def test_cmaes_searches_pd_alphas_order_inside_its_range():
    """For PD^alpha the default search includes alpha, on a logistic scale: x = 0 is the
    params file's alpha, every point stays inside (0, 2), and a run is scored as any."""
    from hexapod_bringup.core.cmaes import _logistic, default_names

    p = load_params(**{"sim.control_period": 1e-3})
    assert default_names(p, "pd_alpha") == ("kp1", "kd1", "kp2", "kd2", "alpha")
    assert default_names(p, "pd_p") == ("kp1", "kd1", "kp2", "kd2")
    assert _logistic(1.0, (0.0, 2.0), 0.0) == pytest.approx(1.0, abs=1e-15)
    assert 0.0 < _logistic(1.0, (0.0, 2.0), -50.0) < _logistic(1.0, (0.0, 2.0), 50.0) <= 2.0
    res = tune_cmaes(p, "pd_alpha", names=("kp1", "alpha"), budget=6, sigma0=1.5, seed=3,
                     popsize=3, duration=1.0, backend=InlineBackend())
    assert res.evaluations == 6 and 0.0 < res.best["alpha"] < 2.0
    alphas = [_logistic(1.0, (0.0, 2.0), float(x[1])) for x in res.search.xs]
    assert all(0.0 < a < 2.0 for a in alphas) and len(set(alphas)) > 1
