"""The controller's input-wait counts (hexapod_control/core/waits.py) and their round trip
through its end summary, which the graph launcher reads back to explain missed ticks."""
from __future__ import annotations

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
