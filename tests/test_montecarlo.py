"""Monte Carlo on uneven ground: Student t intervals cover the true mean, controllers share
each seed's ground (CRN), a seed replays bit for bit, spread 0 is the uniform ground, the
CLI refuses hostile input in one line."""
import json
import math
import subprocess
import sys

import numpy as np
import pytest

from hexapod_bringup.core.montecarlo import monte_carlo, simulate_on_ground
from hexapod_bringup.core.parallel import InlineBackend, ProcessBackend
from hexapod_bringup.core.simulate import simulate
from hexapod_bringup.core.stats import mean_interval, paired_interval, t_cdf, t_quantile
from hexapod_common.core.params import load_params


@pytest.mark.parametrize("df, q975", [(1, 12.7062047362), (2, 4.30265272975),
                                      (5, 2.57058183661), (10, 2.22813885196),
                                      (30, 2.04227245630), (1000, 1.96233908082)])
def test_t_quantiles_match_the_tables(df, q975):
    assert t_quantile(0.975, df) == pytest.approx(q975, abs=1e-8)
    assert t_cdf(q975, df) == pytest.approx(0.975, abs=1e-10)
    assert t_quantile(0.025, df) == pytest.approx(-q975, abs=1e-8)


@pytest.mark.parametrize("n", [5, 20])
def test_the_95_percent_interval_covers_the_true_mean_95_percent_of_the_time(n):
    rng = np.random.default_rng(2026)
    reps = 4000
    hits = sum(mean_interval(rng.normal(3.0, 2.0, n)).contains(3.0) for _ in range(reps))
    # binomial(4000, 0.95): sd 0.34 %; 4 sd either side
    assert abs(hits / reps - 0.95) < 0.014


def test_paired_interval_is_the_interval_of_the_differences_and_skips_nan():
    a = np.array([1.0, 2.0, math.nan, 4.0, 5.0])
    b = np.array([1.5, 2.4, 3.0, 4.6, 5.3])
    d = paired_interval(a, b)
    assert d.n == 4 and d.mean == pytest.approx(0.45)
    ref = mean_interval([0.5, 0.4, 0.6, 0.3])
    assert (d.low, d.high) == pytest.approx((ref.low, ref.high))
    assert mean_interval([1.0]).n == 1 and math.isnan(mean_interval([1.0]).low)


def test_controllers_share_each_seeds_ground_and_backends_agree():
    p = load_params()
    seeds = [4, 9]
    inline = monte_carlo(p, ("pd_p", "pd_pf"), seeds, 0.3, duration=1.5,
                         backend=InlineBackend())
    with ProcessBackend(2) as pool:
        procs = monte_carlo(p, ("pd_p", "pd_pf"), seeds, 0.3, duration=1.5, backend=pool)
    assert json.dumps(inline.as_dict()) == json.dumps(procs.as_dict())
    for k in range(len(seeds)):
        a, b = inline.runs["pd_p"][k].ground, inline.runs["pd_pf"][k].ground
        assert a["seed"] == b["seed"] == seeds[k]
        for fa, fb in zip(a["factors"], b["factors"]):  # per foot: one sequence, two prefixes
            m = min(len(fa), len(fb))
            assert m >= 1 and fa[:m] == fb[:m]
    assert inline.runs["pd_p"][0].ground["factors"] != inline.runs["pd_p"][1].ground["factors"]
    diff = inline.difference("pd_p", "pd_pf", "eps_xH")
    assert diff.n == 2
    assert diff.mean == pytest.approx(np.mean(inline.values("pd_pf", "eps_xH")
                                              - inline.values("pd_p", "eps_xH")))


def test_a_seed_replays_bit_for_bit_and_spread_zero_is_the_uniform_ground():
    p = load_params()
    res = monte_carlo(p, ("pd_pf",), [0, 1, 2], 0.25, duration=1.5)
    again = simulate_on_ground(p, "pd_pf", 1, 0.25, 1.5)
    assert again.indices.as_dict() == res.runs["pd_pf"][1].indices
    assert again.run.ground.as_dict() == res.runs["pd_pf"][1].ground
    flat = simulate(p, "pd_p", 1.5)
    zero = monte_carlo(p, ("pd_p",), [3, 5], 0.0, duration=1.5)
    for r in zero.runs["pd_p"]:
        assert r.indices == flat.indices.as_dict()
    assert zero.interval("pd_p", "eps_xH").half_width == 0.0


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "hexapod_bringup.cli", "montecarlo", *args],
                          capture_output=True, text=True, timeout=300)


@pytest.mark.parametrize("args, words", [
    (["--seeds", "-3"], "--seeds: '-3'"), (["--seeds", "0"], "--seeds: '0'"),
    (["--first-seed", "-1"], "--first-seed: '-1'"), (["--spread", "-5"], "--spread: '-5'"),
    (["--spread", "nan"], "--spread: 'nan'"), (["--controllers", "pd_p,pid"], "'pid'"),
    (["--controllers", "pd_p,pd_p"], "twice"), (["--ground", "-20"], "--ground: '-20'"),
    (["--ground", "100", "--ground-scale", "1"], "not both")])
def test_hostile_cli_input_is_one_line(args, words):
    out = _cli(*args, "--backend", "inline")
    assert out.returncode == 2
    assert out.stdout == "" and len(out.stderr.strip().splitlines()) == 1
    assert words in out.stderr


def test_cli_prints_intervals_and_writes_a_replayable_json(tmp_path):
    path = tmp_path / "mc.json"
    out = _cli("--seeds", "2", "--first-seed", "7", "--spread", "30", "--ground", "200",
               "--t-run", "1.5", "--backend", "inline", "--json", str(path))
    assert out.returncode == 0, out.stderr
    assert "paired t" in out.stdout and "pd_pf - pd_p" in out.stdout
    assert out.stderr == ""  # no progress bar when stdout is not a terminal
    doc = json.loads(path.read_text())
    assert doc["seeds"] == [7, 8] and doc["spread"] == 0.3 and doc["ground_scale"] == 2.0
    run = doc["runs"][1]
    one = _cli("--seeds", "1", "--first-seed", "8", "--spread", "30", "--ground", "200",
               "--t-run", "1.5", "--backend", "inline", "--controllers", "pd_p",
               "--json", "-")
    assert one.returncode == 0, one.stderr
    replay = json.loads(one.stdout)["runs"][0]
    assert replay == run


def _result(diffs, base=0.05):
    from hexapod_bringup.core.montecarlo import McRun, MonteCarloResult

    runs = {"pd_p": [], "pd_pf": []}
    for k, d in enumerate(diffs):  # E8 decides on the stationary hip errors trk_xH + eps_yH
        runs["pd_p"].append(McRun("pd_p", k, "ok", {"trk_xH": base, "eps_yH": 0.0}, {}))
        runs["pd_pf"].append(McRun("pd_pf", k, "ok", {"trk_xH": base + d, "eps_yH": 0.0}, {}))
    return MonteCarloResult(("pd_p", "pd_pf"), tuple(range(len(diffs))), 0.2, 1.0, 400.0, 3.0,
                            runs)


def test_e8_decides_the_winner_by_the_paired_interval_and_plans_seeds():
    from hexapod_bringup.core.montecarlo import McRun, decide, hip_errors

    better = decide(_result([-0.010, -0.012, -0.011, -0.009]), "pd_p", "pd_pf")
    assert better.winner == "pd_pf" and better.difference.high < 0
    worse = decide(_result([0.010, 0.012, 0.011, 0.009]), "pd_p", "pd_pf")
    assert worse.winner == "pd_p"
    noisy = decide(_result([-0.010, 0.012, -0.011, 0.005]), "pd_p", "pd_pf")
    assert noisy.winner is None and noisy.seeds_needed > 4
    # the planning figure: the smallest n with t_{n-1} s / sqrt(n) < |mean|
    d = np.array([-0.010, 0.012, -0.011, 0.005])
    s, m = np.std(d, ddof=1), abs(np.mean(d))
    n = noisy.seeds_needed
    assert t_quantile(0.975, n - 1) * s / math.sqrt(n) < m
    assert t_quantile(0.975, n - 2) * s / math.sqrt(n - 1) >= m
    # the same runs scored on one gait cycle decide on that cycle's numbers
    res = _result([-0.010, -0.012, -0.011, -0.009])
    cyc = {"pd_p": ({"trk_xH": 0.02, "eps_yH": 0.0},),
           "pd_pf": ({"trk_xH": 0.03, "eps_yH": 0.0},)}
    res = type(res)(res.controllers, res.seeds, res.spread, res.ground_scale, res.t_max,
                    res.duration, {c: [McRun(r.controller, r.seed, r.status, r.indices, {},
                                             cyc[c]) for r in v] for c, v in res.runs.items()})
    assert decide(res, "pd_p", "pd_pf").winner == "pd_pf"
    at0 = res.at_cycle(0)
    assert list(hip_errors(at0, "pd_pf")) == [0.03] * 4
    assert decide(at0, "pd_p", "pd_pf").winner == "pd_p"  # on cycle 0 PD-P is lower
    assert res.at_cycle(1).diverged("pd_p") == 4  # no cycle 1: no indices there


def test_cli_grid_of_grounds_and_spreads_compares_two_controllers():
    out = _cli("--seeds", "2", "--ground", "100,300", "--spread", "25", "--t-run", "1.5",
               "--backend", "inline", "--json", "-")
    assert out.returncode == 0, out.stderr
    doc = json.loads(out.stdout)
    assert [(q["ground_percent"], q["spread"]) for q in doc["points"]] == [(100.0, 0.25),
                                                                        (300.0, 0.25)]
    for q in doc["points"]:
        assert q["winner"] in ("pd_p", "pd_pf", None) and len(q["runs"]) == 4
    bad = _cli("--controllers", "pd_p", "--ground", "100,300", "--backend", "inline")
    assert bad.returncode == 2 and "exactly two controllers" in bad.stderr
