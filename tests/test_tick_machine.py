"""The sim's tick state machine (core/tick_machine.py) without processes: lockstep, realtime,
late, missed, hold, fallback, switch and takeover."""
from __future__ import annotations

import numpy as np
import pytest

from hexapod_common.core import labels as L
from hexapod_sim.core.actuator import saturate
from hexapod_sim.core.physics import Physics
from hexapod_common.core.layout import O_THV, O_TQ, P_TMAX
from hexapod_common.core.params import HexapodParams, load_params
from hexapod_sim.core.tick_machine import (FIRST_TICK_WAIT, LIVENESS_LOOK, SWITCH_WINDOW,
                                           Outcome, TickMachine, Wait)

PERIOD = 1e-3
FAST = {"sim.dt": 1e-4, "sim.control_period": PERIOD, "sim.hold_time": 0.005,
        "run.duration": 0.05}


class Recorder:
    """Hooks and log of a machine: what the shell would be told."""

    def __init__(self) -> None:
        self.lines: list[tuple[str, str]] = []
        self.boundaries: list[int] = []
        self.switches: list[tuple[int, str, str]] = []
        self.readied: list[int] = []
        self.at_boundary_do = None

    def info(self, message: str) -> None:
        self.lines.append(("info", message))

    def warning(self, message: str) -> None:
        self.lines.append(("warning", message))

    def error(self, message: str) -> None:
        self.lines.append(("error", message))

    def at_boundary(self, tick: int) -> None:
        self.boundaries.append(tick)
        if self.at_boundary_do is not None:
            self.at_boundary_do(tick)

    def switched(self, tick: int, old: str, new: str) -> None:
        self.switches.append((tick, old, new))

    def ready(self, tick: int) -> None:
        self.readied.append(tick)


def machine(mode: str = "lockstep", stop_at_end: bool = False,
            **overrides: object) -> tuple[TickMachine, Recorder, HexapodParams]:
    p = load_params(**{**FAST, "sim.mode": mode, **overrides})
    rec = Recorder()
    m = TickMachine(Physics(p), lambda: p, rec, rec, stop_at_end=stop_at_end)
    return m, rec, p


def publish(m: TickMachine, now: float) -> tuple[Wait, float, str]:
    """What the shell does per tick: sample, send; the wait and the states' frame_id."""
    _, _, _, frame = m.sample()
    m.sending(now)
    wait, when = m.sent(now)
    return wait, when, frame


def demand(k: int) -> np.ndarray:
    return np.full(12, 10.0 + k)


def test_lockstep_applies_each_command_at_once_and_equals_the_engine() -> None:
    m, rec, p = machine()
    ref = Physics(p)
    torque = np.zeros((6, 2))
    m.start(0.0)
    for k in range(10):
        wait, when, frame = publish(m, float(k))
        assert (wait, when, frame) == (Wait.TIMEOUT, k + LIVENESS_LOOK, "pd_pf")
        assert m.command(m.stamp, "pd_pf", demand(k), k + 1.1e-4) is Outcome.SEND
        saturate(demand(k).reshape(6, 2), ref.P[P_TMAX], torque)
        ref.advance_tick(torque)
    assert m.tick == 10 and np.array_equal(m.physics.observe(), ref.observe())  # bit for bit
    assert (m.missed, m.late, m.foreign) == (0, 0, 0) and m.not_commanded == []
    assert rec.readied == list(range(1, 11)) and rec.boundaries == list(range(1, 11))
    assert m.latency_ms(0.5) == pytest.approx(0.12)  # 0.11 ms round trips: bin [0.10, 0.12) ms


def test_paced_lockstep_releases_each_tick_a_period_over_max_rtf_after_the_last() -> None:
    m, _, p = machine()
    assert m.release_at() == 0.0  # the default: unpaced, each tick goes out at once
    m, _, p = machine(**{"sim.lockstep_max_rtf": 0.25})
    m.start(0.0)
    for k in range(3):
        sent = 10.0 * k  # a graph slower than the pace is not made to catch up
        publish(m, sent)
        assert m.command(m.stamp, "pd_pf", demand(k), sent + 1e-4) is Outcome.SEND
        assert m.release_at() == pytest.approx(sent + PERIOD / 0.25)
    with pytest.raises(Exception, match="sim.lockstep_max_rtf"):
        machine(**{"sim.lockstep_max_rtf": -1.0})


def test_missed_tick_holds_the_torque_and_says_so_in_the_next_frame() -> None:
    m, rec, p = machine()
    m.start(0.0)
    publish(m, 0.0)
    m.command(m.stamp, "pd_pf", demand(0), 0.0)
    held = m.torque.copy()
    publish(m, 1.0)
    m.timeout()  # no command for tick 1
    assert m.missed == 1 and m.silent_ticks == 1 and np.array_equal(m.torque, held)
    wait, when, frame = publish(m, 2.0)
    assert frame == L.state_frame("pd_pf", L.HELD) == "pd_pf/held"
    assert (wait, when) == (Wait.TIMEOUT, 2.0 + PERIOD)  # while silent: one period a tick
    assert np.array_equal(m.physics.observe()[O_TQ], held)
    assert m.not_commanded == [[1, 2]] and rec.lines[0][0] == "warning"
    assert m.command(m.stamp, "pd_pf", demand(2), 2.0) is Outcome.SEND  # back
    assert m.silent_ticks == 0 and publish(m, 3.0)[2] == "pd_pf"
    assert "answers again at tick 2" in rec.lines[-1][1]


def test_lockstep_waits_for_a_living_controller_up_to_the_cap_and_no_longer() -> None:
    m, rec, p = machine(**{"sim.lockstep_timeout": 3.0})
    m.start(0.0)
    publish(m, 0.0)
    m.command(m.stamp, "pd_pf", demand(0), 0.0)
    wait, when, _ = publish(m, 1.0)
    assert (wait, when) == (Wait.TIMEOUT, 1.0 + LIVENESS_LOOK)
    # alive (stopped, starved): look again every LIVENESS_LOOK s, up to the cap
    assert m.waiting(1.5, alive=True) == 2.0
    assert m.waiting(3.9, alive=True) == 4.0  # the cap: 3 s after the tick went out
    assert m.command(m.stamp, "pd_pf", demand(1), 3.95) is Outcome.SEND  # it answers
    assert m.missed == 0 and m.long_waits == 1 and m.longest_wait == pytest.approx(2.9)
    assert m.waiting(4.0, alive=True) is None  # answered: nothing to wait for
    # a controller that has left: missed at the first look, as before
    publish(m, 5.0)
    assert m.waiting(5.5, alive=False) is None
    m.timeout()
    assert m.missed == 1 and m.cap_hits == 0
    # silent already: one period a tick, whatever its liveness
    publish(m, 6.0)
    assert m.waiting(6.001, alive=True) is None
    m.timeout()
    assert m.missed == 2
    # alive but hung past the cap: missed, and said
    m2, rec2, _ = machine(**{"sim.lockstep_timeout": 1.0})
    m2.start(0.0)
    publish(m2, 0.0)
    assert m2.waiting(0.5, alive=True) == 1.0
    assert m2.waiting(1.0, alive=True) is None and m2.cap_hits == 1
    assert "sim.lockstep_timeout (1 s) reached" in rec2.lines[-1][1]
    assert rec2.lines[-1][0] == "warning"


def test_silence_beyond_hold_time_falls_back_to_joint_damping_until_a_command() -> None:
    m, rec, p = machine()
    m.start(0.0)
    publish(m, 0.0)
    m.command(m.stamp, "pd_pf", demand(0), 0.0)
    hold = round(p.sim.hold_time / PERIOD)
    for k in range(1, hold + 3):
        publish(m, float(k))
        obs = m.obs.copy()
        m.timeout()
    assert m.fallback and m.fallback_episodes == 1
    want = np.empty((6, 2))
    saturate(-p.sim.fallback_damping * obs[O_THV], m.physics.P[P_TMAX], want)
    assert np.array_equal(m.torque, want)  # the last tick's torque: damping of its sample
    assert publish(m, 100.0)[2] == "pd_pf/fallback"
    assert m.fallback_ranges == [[hold, hold + 3]] and m.not_commanded == [[1, hold + 3]]
    assert any(level == "error" and "falling back to joint damping" in text
               for level, text in rec.lines)
    m.command(m.stamp, "pd_pf", demand(0), 100.0)
    assert not m.fallback and publish(m, 101.0)[2] == "pd_pf"
    assert m.summary_doc()["fallback_ticks"] == [[hold, hold + 3]]


def test_realtime_on_time_late_and_missed() -> None:
    m, rec, p = machine("realtime")
    m.start(0.0)
    wait, when, _ = publish(m, 0.0)
    assert (wait, when) == (Wait.PERIOD_END, FIRST_TICK_WAIT)  # tick 0 waits
    assert m.command(0, "pd_pf", demand(0), 0.2) is Outcome.SCHEDULE  # the clock starts
    assert m.t0 == pytest.approx(0.2 - PERIOD)
    m.period_end(0.2)  # advanced already: nothing more is applied
    assert m.tick == 1 and m.on_time == 1
    wait, due, _ = publish(m, 0.2)
    assert (wait, due) == (Wait.PERIOD_END, pytest.approx(m.t0 + 2 * PERIOD))
    assert m.command(m.stamp, "pd_pf", demand(1), due - 1e-4) is Outcome.READY  # on time
    m.period_end(due)
    _, due, _ = publish(m, due)
    stamp2 = m.stamp
    m.period_end(due)  # tick 2's command did not come in its period: missed, held
    assert (m.missed, m.on_time) == (1, 2) and m.silent_ticks == 1
    _, due, frame = publish(m, due)
    assert frame == "pd_pf/held"
    assert m.command(stamp2, "pd_pf", demand(2), due - 5e-4) is Outcome.LATE  # too late
    assert m.late == 1 and m.newest is not None
    m.period_end(due)  # tick 3's period ends: the newest (late) command is applied
    assert m.missed == 2 and m.silent_ticks == 0 and m.newest is None
    want = np.empty((6, 2))
    saturate(demand(2).reshape(6, 2), m.physics.P[P_TMAX], want)
    assert np.array_equal(m.torque, want)
    assert publish(m, due)[2] == "pd_pf"  # a late command is the controller's own
    assert m.not_commanded == [[2, 3]]


def test_realtime_resyncs_when_far_behind() -> None:
    m, _, _ = machine("realtime")
    m.start(0.0)
    publish(m, 0.0)
    m.command(0, "pd_pf", demand(0), 0.0)
    wait, due, _ = publish(m, 1.0)  # a second late: more than RESYNC_TICKS periods behind
    assert m.resyncs == 1 and due == pytest.approx(1.0 + PERIOD)


def test_switch_at_the_next_boundary_and_the_new_controller_takes_over() -> None:
    m, rec, _ = machine()
    m.start(0.0)
    publish(m, 0.0)
    m.request_switch("pd_p")
    assert m.command(m.stamp, "pd_p", demand(0), 0.0) is Outcome.FOREIGN  # not yet
    assert m.command(m.stamp, "pd_pf", demand(0), 0.0) is Outcome.SEND  # old one's last
    assert m.in_charge == "pd_p" and rec.switches == [(1, "pd_pf", "pd_p")]
    _, _, frame = publish(m, 1.0)
    assert frame == "pd_p"
    assert m.command(m.stamp, "pd_pf", demand(1), 1.0) is Outcome.FOREIGN
    assert m.command(m.stamp, "pd_p", demand(1), 1.0) is Outcome.SEND  # takeover, no loss
    assert (m.missed, m.missed_after_switch, m.foreign) == (0, 0, 2)
    assert m.summary_doc()["switches"] == [{"tick": 1, "from": "pd_pf", "to": "pd_p"}]


def test_a_takeover_that_misses_is_counted_against_the_switch() -> None:
    m, _, _ = machine()
    m.start(0.0)
    publish(m, 0.0)
    m.request_switch("pd_p")
    m.command(m.stamp, "pd_pf", demand(0), 0.0)
    for k in range(1, SWITCH_WINDOW + 2):
        publish(m, float(k))
        m.timeout()  # the new controller does not answer
    assert m.missed == SWITCH_WINDOW + 1 and m.missed_after_switch == SWITCH_WINDOW


def test_switch_and_parameters_requested_at_a_boundary_apply_there() -> None:
    m, rec, p = machine()
    harder = load_params(**{**FAST, "ground.scale": 2.0})
    rec.at_boundary_do = lambda k: (m.request_switch("pd_p"), m.request_params(harder)) \
        if k == 2 else None  # as the scripted switch and the switch channel do
    m.start(0.0)
    for k in range(3):
        publish(m, float(k))
        m.command(m.stamp, m.in_charge, demand(k), float(k))
    assert rec.switches == [(2, "pd_pf", "pd_p")] and m.pending_params is None
    assert m.physics.P.tolist() == Physics(harder).P.tolist()


def test_commands_ahead_stale_or_after_the_end() -> None:
    m, _, _ = machine(stop_at_end=True, **{"run.duration": 0.002})
    assert m.command(0, "pd_pf", demand(0), 0.0) is Outcome.STALE  # before the start
    m.start(0.0)
    publish(m, 0.0)
    assert m.command(m.stamp + 1_000_000, "pd_pf", demand(0), 0.0) is Outcome.AHEAD
    assert m.command(m.stamp, "pd_pf", demand(0), 0.0) is Outcome.SEND
    publish(m, 1.0)
    m.command(m.stamp, "pd_pf", demand(1), 1.0)
    assert m.command(m.stamp - 1_000_000, "pd_pf", demand(1), 1.0) is Outcome.LATE
    wait, _, _ = publish(m, 2.0)
    assert wait is Wait.STOP and m.finished
    assert m.command(m.stamp, "pd_pf", demand(2), 2.0) is Outcome.IGNORED
