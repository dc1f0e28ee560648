"""The controller's input-wait counts (hexapod_control/core/waits.py) and their round trip
through its end summary, which the graph launcher reads back to explain missed ticks."""
from __future__ import annotations

import math

import pytest

from hexapod_control.core.waits import InputWaits, parse


def test_counts_by_missing_input_and_read_back_from_a_log():
    w = InputWaits()
    w.count(True, False)
    w.count(True, True)
    w.count(False, True)
    w.given_up = 2
    assert (w.waited, w.reference, w.forces) == (3, 2, 2)
    log = (f"[INFO] [1.0] [pd_pf_controller]: stopping after 7 commands (0 waited for their "
           f"reference or foot forces: 0 for the reference, 0 for the foot forces; 0 states "
           f"given up unanswered, their inputs never came; 0 inputs ...)\n"
           f"[INFO] [2.0] [pd_pf_controller]: stopping after 7 commands ({w.text()}; 3 "
           f"inputs of ticks no state needed skipped unchecked)\n")
    assert parse(log) == w  # the last summary in the log
    assert parse("no summary here") is None


def test_the_cause_names_the_missing_input_and_stays_quiet_for_tick_0():
    assert InputWaits(1, 1, 0, 0).cause() == ""  # tick 0 waits for the first reference
    assert InputWaits().cause() == ""
    cause = InputWaits(40, 40, 0, 12).cause()
    assert cause.startswith("40 states waited (40 for their reference (the trajectory "
                            "generator behind")
    assert cause.endswith("; 12 given up unanswered")
    assert "foot forces" not in cause
    assert "3 for their foot forces" in InputWaits(3, 0, 3, 0).cause()


def test_a_state_answered_at_once_is_no_wait_and_the_warning_names_the_missing_input():
    """A state answered at once while an older one still waits (lockstep after a missed tick:
    the sim went on) is no wait: not counted, no warning (it read 'the  of tick 805788 came
    after its state'). A state that waits is named with the input it waits for."""
    import types

    pytest.importorskip("rclpy", reason="the controller node needs rclpy (scripts/setup.sh)")
    from hexapod_control.controller_node import WARN_AFTER, ControllerNode

    said: list[str] = []
    period = 1_000_000
    node = types.SimpleNamespace(
        refs={5 * period: object()}, forces={5 * period: object(), 6 * period: object()},
        waits=InputWaits(waited=WARN_AFTER), warned_at=-math.inf, period_ns=period,
        log=types.SimpleNamespace(warning=said.append))
    ControllerNode._count_wait(node, 5 * period)  # both inputs there: answered at once
    assert said == [] and node.waits == InputWaits(waited=WARN_AFTER)
    ControllerNode._count_wait(node, 6 * period)  # its reference is late
    assert node.waits == InputWaits(waited=WARN_AFTER + 1, reference=1)
    assert len(said) == 1 and said[0].startswith(
        "the reference of tick 6 came after its state (the newest reference is of tick 5)")
