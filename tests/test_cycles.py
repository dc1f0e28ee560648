"""The one cycle scorer (core/cycles.py) and the one labelling rule (core/labels.py)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from graph.bag_checks import bag_qos  # tests/graph: the same check of graph bags
from hexapod_control.core.closed_loop import run
from hexapod_common.core import cdr
from hexapod_metrics.core.analysis import analyze_bag
from hexapod_metrics.core.cycles import CYCLE_TOPICS, CycleScorer, TickLabels
from hexapod_metrics.core.indices import indices_from_obs
from hexapod_metrics.core.recording import write_run_bag
from hexapod_common.core import labels as L
from hexapod_common.core import topics as T
from hexapod_common.core.params import load_params

#: One worker runs the module (its module-scoped fixture once): scripts/test.sh uses
#: pytest-xdist's loadgroup distribution.
pytestmark = pytest.mark.xdist_group("test_cycles")

FAST = {"sim.dt": 1e-4, "sim.control_period": 1e-3}


@pytest.mark.parametrize("frame, parsed", [
    ("pd_pf", ("pd_pf", L.COMMANDED)), ("pd_p/held", ("pd_p", L.HELD)),
    ("pd_pf/fallback", ("pd_pf", L.FALLBACK)), ("", (L.UNKNOWN, L.COMMANDED))])
def test_state_frames_round_trip(frame: str, parsed: tuple[str, str]) -> None:
    assert L.parse_state_frame(frame) == parsed
    if frame:
        assert L.state_frame(*parsed) == frame
    assert L.in_charge(frame) == parsed[0]


def test_a_clean_frame_is_the_bare_name_and_a_bad_source_is_refused() -> None:
    assert L.state_frame("pd_pf") == "pd_pf"  # clean runs: the bytes of an unlabelled run
    with pytest.raises(ValueError, match="torque source 'late'"):
        L.state_frame("pd_pf", "late")


@pytest.mark.parametrize("controllers, sources, label", [
    (["pd_pf"] * 4, [""] * 4, "pd_pf"),
    (["pd_pf", "pd_pf", "pd_p", "pd_p"], [""] * 4, "pd_pf->pd_p"),
    (["pd_pf"] * 4, ["", "held", "held", ""], "mixed(pd_pf+2 uncommanded)"),
    (["pd_pf"] * 4, ["held", "held", "fallback", "fallback"], "fallback"),
    (["pd_pf"] * 4, ["held"] * 4, "held"),
    (["pd_pf", "pd_p", "pd_p", "pd_p"], ["", "held", "", ""],
     "mixed(pd_pf->pd_p+1 uncommanded)"),
])
def test_cycle_label_never_credits_a_controller_with_uncommanded_torques(
        controllers: list[str], sources: list[str], label: str) -> None:
    got, _, uncommanded = L.cycle_label(controllers, sources)
    assert got == label and uncommanded == sum(s != "" for s in sources)


def test_tick_labels_source_of_sample_k_is_the_torque_of_tick_k_minus_1() -> None:
    lab = TickLabels()
    for k, frame in enumerate(["pd_pf", "pd_pf", "pd_pf/held", "pd_pf/fallback", "pd_pf",
                               "pd_p", "pd_p"]):
        lab.add(k, frame)
    controllers, sources = lab.at(np.arange(6))
    assert list(controllers) == ["pd_pf"] * 5 + ["pd_p"]
    assert list(sources) == ["", "held", "fallback", "", "", ""]
    assert lab.history == [(0, "pd_pf"), (5, "pd_p")]


@pytest.fixture(scope="module")
def clean_run():
    p = load_params(**FAST)
    return p, run(p, "pd_pf", 3.0)


def _messages(r, k: int, frame: str) -> dict[str, bytes]:
    stamp = T.stamp_ns(r.t[k])
    out = {}
    for topic in T.STATE_TOPICS:
        c = T.state_columns(r.obs[k], topic)
        out[topic] = cdr.encode_joint_state(stamp, c.names, c.position, c.velocity, c.effort,
                                            frame if topic == T.JOINT_STATES else "")
    ref = r.reference
    c = T.reference_columns(ref.theta[k], ref.theta_vel[k], ref.hip[k], ref.hip_vel[k],
                            ref.foot[k], ref.foot_vel[k])
    out[T.REFERENCE] = cdr.encode_joint_state(stamp, c.names, c.position, c.velocity, c.effort)
    return out


def test_scorer_per_message_equals_the_engine_and_labels_held_ticks(clean_run) -> None:
    _p, r = clean_run
    n = 1000
    held = set(range(1500, 1510))  # torque ticks 1500..1509 "held" -> cycle 1 is mixed
    fallback = set(range(2000, 3000))  # all of cycle 2
    scorer = CycleScorer(n, 1e-3, gap_ticks=n)
    cycles = []
    for k in range(r.obs.shape[0]):
        j = k - 1  # the torque this sample carries
        source = L.HELD if j in held else L.FALLBACK if j in fallback else L.COMMANDED
        frame = L.state_frame("pd_pf", source)
        scorer.add_frame(k, frame)
        for topic, data in _messages(r, k, frame).items():
            scorer.add_raw(topic, k, data)
        cycles += scorer.take()
    assert [c.controller for c in cycles] == ["pd_pf", "mixed(pd_pf+10 uncommanded)",
                                              "fallback"]
    assert [c.uncommanded for c in cycles] == [0, 10, 1000]
    assert all(c.in_charge == "pd_pf" for c in cycles)
    for c in cycles:  # the numbers are the engine's, bit for bit
        sl = slice(c.cycle * n, (c.cycle + 1) * n + 1)
        assert c.indices == indices_from_obs(r.obs[sl], r.reference.hip[sl],
                                             r.reference.foot[sl], 1e-3)
    assert np.isnan(cycles[0].lag_growth)
    assert cycles[1].lag_growth == cycles[1].indices.lag_xH - cycles[0].indices.lag_xH


def test_scorer_from_blocks_equals_per_message_and_waits_for_every_topic(clean_run) -> None:
    _, r = clean_run
    n = 1000
    per_msg = CycleScorer(n, 1e-3)
    blocks = CycleScorer(n, 1e-3)
    raw: dict[str, list[bytes]] = {t: [] for t in CYCLE_TOPICS}
    for k in range(r.obs.shape[0]):
        for topic, data in _messages(r, k, "pd_pf").items():
            per_msg.add_raw(topic, k, data)
            raw[topic].append(data)
    per_msg.add_frame(0, "pd_pf")
    blocks.add_frame(0, "pd_pf")
    got = []
    for topic in CYCLE_TOPICS:  # a bag's chunk: one topic after the other
        assert not got  # no cycle before every topic reached its end
        a = cdr.decode_joint_state_batch(raw[topic])
        blocks.add_block(topic, np.arange(len(raw[topic])), a.position, a.velocity, a.effort)
        got += blocks.take()
    want = per_msg.take()
    assert [(c.cycle, c.controller, c.indices) for c in got] == [
        (c.cycle, c.controller, c.indices) for c in want] and len(got) == 3


def test_a_gap_gives_a_cycle_without_sums_and_scoring_goes_on(clean_run) -> None:
    _, r = clean_run
    n = 1000
    scorer = CycleScorer(n, 1e-3, gap_ticks=n)
    scorer.add_frame(0, "pd_pf")
    out = []
    for k in range(r.obs.shape[0]):
        for topic, data in _messages(r, k, "pd_pf").items():
            if topic == T.HIP_STATES and 1200 <= k < 1210:
                continue  # lost
            scorer.add_raw(topic, k, data)
        out += scorer.take()
    assert [(c.cycle, c.sums is None, c.missing) for c in out] == [
        (0, False, 0), (1, True, 10), (2, False, 0)]


def test_simulate_bag_carries_the_topic_tables_qos(tmp_path: Path, clean_run) -> None:
    _p, r = clean_run
    bag = write_run_bag(r, tmp_path / "bag")
    assert bag_qos(bag) == {t: s.preset for t, s in T.TOPICS.items()
                            if t not in (T.STATUS, T.MARKERS)}
    a = analyze_bag(bag)
    assert [c.controller for c in a.cycles] == ["pd_pf"] * 3
    assert [(c, who) for c, who, _ in a.online] == [(0, "pd_pf"), (1, "pd_pf"), (2, "pd_pf")]
