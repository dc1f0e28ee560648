"""Lockstep's pacing by the recorder (hexapod_sim/core/recorder_pace.py), without processes."""
from __future__ import annotations

import pytest

from hexapod_common.core import topics as T
from hexapod_sim.core.recorder_pace import RecorderPace


def test_a_tick_goes_out_until_the_recorder_is_heard_and_while_it_keeps_up():
    p = RecorderPace(lag=100, patience=5.0)
    assert p.hold_until(10_000, 0.0) is None  # never heard: no recorder to wait for
    p.heard(0, 1.0, 10_000)
    assert p.hold_until(100, 1.0) is None  # 100 behind: allowed
    assert p.hold_until(150, 1.0) == pytest.approx(6.0)  # 150 behind: held
    assert p.holding and p.holds == 1
    assert p.hold_until(150, 2.0) == pytest.approx(6.0)  # still the same hold
    p.heard(20, 3.0, 10_000)
    assert p.hold_until(150, 3.0) == pytest.approx(8.0)  # heard, still behind: longer
    assert p.holds == 1
    p.heard(10, 3.5, 10_000)  # an older report never takes progress back
    assert p.recorded == 20
    p.heard(60, 4.0, 10_000)
    assert p.hold_until(150, 4.0) is None and not p.holding
    assert p.as_dict() == {"recorder_holds": 1, "recorder_held_s": 3.0, "recorder_given_up": 0}


def test_a_silent_recorder_is_given_up_on_until_it_speaks_again():
    p = RecorderPace(lag=100, patience=5.0)
    p.heard(0, 0.0, 10_000)
    assert p.hold_until(500, 1.0) == pytest.approx(5.0)
    assert p.hold_until(500, 5.0) is None  # silent for 5 s: go on
    assert p.gave_up == 1 and p.recorded is None and p.held_s == pytest.approx(4.0)
    assert p.hold_until(5_000, 6.0) is None  # not waited for any longer...
    p.heard(200, 7.0, 10_000)
    assert p.hold_until(5_000, 7.0) == pytest.approx(12.0)  # ... until it speaks again
    assert p.holds == 2


def test_a_recorder_that_left_the_graph_is_not_waited_for():
    p = RecorderPace(lag=100, patience=5.0)
    p.heard(0, 0.0, 10_000)
    assert p.hold_until(500, 1.0) is not None
    p.forget(1.5)
    assert not p.holding and p.held_s == pytest.approx(0.5) and p.gave_up == 0
    assert p.hold_until(500, 1.5) is None
    p.heard(450, 2.0, 10_000)  # a recorder (re)joined
    assert p.hold_until(500, 2.0) is None and p.hold_until(600, 2.0) is not None


def test_a_report_past_the_current_tick_counts_as_the_current_tick():
    # a signed stamp far ahead (a key holder's) cannot end the pacing: it counts as the tick
    # the sim is at, and the sim holds again once it is `lag` ticks past that
    p = RecorderPace(lag=100, patience=5.0)
    p.heard(10**9, 0.0, 50)
    assert p.recorded == 50
    assert p.hold_until(150, 0.5) is None
    assert p.hold_until(151, 0.5) == pytest.approx(5.0) and p.holding
    p.heard(10**9, 1.0, 151)  # again: only up to where the sim is
    assert p.recorded == 151 and p.hold_until(151, 1.0) is None
    assert p.hold_until(252, 1.0) is not None


def test_the_lag_stays_inside_what_the_publishers_keep_for_the_recorder():
    # a held tick's recorder is at most RECORDER_LAG + one report behind: the writers'
    # histories (HISTORY_DEPTH ticks) still hold every message it has not taken
    assert T.RECORDER_LAG + T.RECORDED_EVERY < T.HISTORY_DEPTH // 2


def test_a_silent_recorder_is_borne_while_on_the_graph_and_let_go_once_it_has_left():
    p = RecorderPace(lag=100, patience=5.0)
    p.heard(0, 0.0, 10_000)
    assert p.behind(500) and not p.behind(100)
    on_graph = [True]
    assert p.hold_until(500, 1.0, lambda: on_graph[0], cap=30.0) == pytest.approx(5.0)
    # silent for 5 s but still on the graph (stopped, starved): borne up to the cap
    assert p.hold_until(500, 5.0, lambda: on_graph[0], cap=30.0) == pytest.approx(30.0)
    on_graph[0] = False  # its lease ran out: it left, it is not given up on
    assert p.hold_until(500, 6.0, lambda: on_graph[0], cap=30.0) is None
    assert p.left == 1 and p.gave_up == 0 and p.recorded is None and not p.holding
    assert p.held_s == pytest.approx(5.0)
