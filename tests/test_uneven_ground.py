"""Uneven ground: factors per foot and touchdown, spread 0 = uniform ground bit for bit,
a seed replays bit for bit, recorded draws replay the run."""
import numpy as np
import pytest

from hexapod_common.core.errors import ParameterError
from hexapod_common.core.layout import STATE_SIZE
from hexapod_common.core.params import N_LEGS, load_params
from hexapod_control.core.closed_loop import run
from hexapod_sim.core.engine import initial_state
from hexapod_sim.core.physics import Physics
from hexapod_sim.core.uneven_ground import GroundDraws, ground_factors, touchdowns


def _same(a, b):
    return np.array_equal(a.obs, b.obs, equal_nan=True) and np.array_equal(
        a.command, b.command, equal_nan=True)


@pytest.mark.parametrize("controller", ["pd_p", "pd_pf"])
def test_spread_zero_is_the_uniform_ground_bit_for_bit(controller):
    p = load_params(**{"ground.scale": 2.0})
    flat = run(p, controller, 1.5)
    zero = run(p, controller, 1.5, ground=GroundDraws.draw(7, 0.0, 40))
    assert _same(flat, zero)
    assert flat.ground is None and zero.ground is not None
    assert np.all(zero.ground.draws.factors == 1.0)
    assert min(zero.ground.touchdowns) >= 1


def test_a_seed_replays_bit_for_bit_and_the_recorded_draws_replay_the_run():
    p = load_params()
    a = run(p, "pd_pf", 1.5, ground=GroundDraws.draw(11, 0.3, 40))
    b = run(p, "pd_pf", 1.5, ground=GroundDraws.draw(11, 0.3, 40))
    assert _same(a, b)
    other = run(p, "pd_pf", 1.5, ground=GroundDraws.draw(12, 0.3, 40))
    assert not np.array_equal(a.obs, other.obs)
    flat = run(p, "pd_pf", 1.5)
    assert not np.array_equal(a.obs, flat.obs)
    # replay from the record alone: the used pairs, padded with anything (never reached)
    used = a.ground.used()
    m = max(len(u) for u in used)
    factors = np.full((N_LEGS, m + 1, 2), 123.0)
    for i, u in enumerate(used):
        factors[i, :len(u)] = u
    replay = run(p, "pd_pf", 1.5, ground=GroundDraws.given(factors))
    assert _same(a, replay)
    assert replay.ground.touchdowns == a.ground.touchdowns


def test_more_draws_extend_fewer_and_factors_are_lognormal_with_median_one():
    short, long = GroundDraws.draw(5, 0.4, 10), GroundDraws.draw(5, 0.4, 4000)
    assert np.array_equal(short.factors, long.factors[:, :10])
    logs = np.log(long.factors)
    assert abs(np.median(logs)) < 0.02
    assert np.std(logs) == pytest.approx(0.4, rel=0.02)
    # feet and directions are independent streams
    assert abs(np.corrcoef(logs[0, :, 0], logs[1, :, 0])[0, 1]) < 0.05
    assert abs(np.corrcoef(logs[0, :, 0], logs[0, :, 1])[0, 1]) < 0.05


def test_the_engine_uses_the_pair_of_the_current_touchdown():
    draws = GroundDraws.given(np.arange(1, 1 + N_LEGS * 3 * 2, dtype=float).reshape(N_LEGS, 3, 2))
    s = draws.attach(initial_state(load_params()))
    assert s.shape == (STATE_SIZE + N_LEGS + N_LEGS * 3 * 2,)
    assert ground_factors(s, 2) == (13.0, 14.0)  # before any touchdown: the first pair
    s[STATE_SIZE + 2] = 2.0  # two touchdowns so far
    assert ground_factors(s, 2) == (15.0, 16.0)
    s[STATE_SIZE + 2] = 9.0  # beyond the draws: the last pair, and the record says so
    assert ground_factors(s, 2) == (17.0, 18.0)
    assert list(touchdowns(s)) == [0, 0, 9, 0, 0, 0]
    assert ground_factors(initial_state(load_params()), 0) == (1.0, 1.0)


def test_a_run_with_too_few_draws_says_it_overflowed():
    r = run(load_params(), "pd_p", 1.5, ground=GroundDraws.draw(1, 0.2, 1))
    assert r.ground.overflowed


def test_physics_object_steps_uneven_ground_like_the_closed_loop():
    """The sim node's stepping object takes the same state tail (ROS-free core)."""
    p = load_params()
    draws = GroundDraws.draw(3, 0.3, 40)
    ph = Physics(p)
    ph.state = draws.attach(ph.state)
    for _ in range(3000):
        ph.observe()
        ph.advance_tick(np.zeros((N_LEGS, 2)))
    assert touchdowns(ph.state).sum() >= 3


@pytest.mark.parametrize("seed, spread, match", [
    (-1, 0.1, "ground.seed"), (1.5, 0.1, "ground.seed"), (True, 0.1, "ground.seed"),
    (0, -0.1, "ground.spread"), (0, float("nan"), "ground.spread"), (0, 2.5, r"\[0, 2\]")])
def test_bad_seeds_and_spreads_are_refused_with_their_names(seed, spread, match):
    with pytest.raises(ParameterError, match=match):
        GroundDraws.draw(seed, spread, 4)


def test_given_factors_must_be_positive_and_shaped_per_foot():
    with pytest.raises(ParameterError, match="ground.factors"):
        GroundDraws.given(np.ones((5, 3, 2)))
    with pytest.raises(ParameterError, match="finite positive"):
        GroundDraws.given(np.zeros((N_LEGS, 3, 2)))
