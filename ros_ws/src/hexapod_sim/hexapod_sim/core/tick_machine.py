"""The sim's tick state machine: which torque each tick applies, and when the next tick goes.

ROS-free (the node, sim_node.py, publishes and receives; this decides). Per tick k the shell
publishes the sample of tick k (:meth:`TickMachine.sample`) between :meth:`sending` and
:meth:`sent` (which says until when to wait), and passes every command (:meth:`command`)
and every expired wait (:meth:`timeout` in lockstep, :meth:`period_end` in realtime) on.
Times are wall seconds (``time.monotonic``), stamps integer nanoseconds of simulated time.

* lockstep: tick k+1 is computed as soon as the command of tick k is applied (and sent at
  once, or, with ``sim.lockstep_max_rtf`` > 0, not before :meth:`release_at`). A tick waits
  for its command while the nodes it needs are alive (the shell says: :meth:`waiting`, asked
  every :data:`LIVENESS_LOOK` s), up to ``sim.lockstep_timeout`` (a cap, reported when hit):
  a stopped or starved process delays the run, it does not change it. Once they have left
  (or the cap is hit) the tick is *missed* and the last torque *held*; while the controller
  is silent, each tick waits one period; after ``sim.hold_time`` of silence the
  torque is the joint-damping *fallback* -sim.fallback_damping * dtheta (saturated). The first
  valid command ends both.
* realtime: ticks are due at t0 + k * period (tick 0 waits as in lockstep and starts the
  schedule); a command in its period is applied at once and the next tick computed ahead
  (*on time*); at the end of a period without it (*missed*) the newest command of the
  controller in charge is applied (one that came after its period counts as *late*), else
  the torque is held; the schedule is re-anchored after ``RESYNC_TICKS`` periods behind.
* switch: a new controller in charge (:meth:`request_switch`) takes over at the next tick
  boundary: the next sample names it, it answers that sample (*takeover*); misses in the next
  ``SWITCH_WINDOW`` ticks are counted apart. Live parameters (:meth:`request_params`) apply
  at the tick boundary too.

Every torque that was not a command of the controller in charge (held or fallback) is kept
in tick ranges and named in the next sample's frame_id (core/labels.py).
"""
from __future__ import annotations

from collections.abc import Callable
from enum import Enum
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from hexapod_common.core import labels as L
from hexapod_common.core import trace as _trace
from .actuator import saturate
from .physics import Physics
from hexapod_common.core.layout import C_DQREF, C_KD, C_KF, C_KP, C_QREF, C_TFF, O_THV, P_TMAX
from hexapod_common.core.params import N_LEGS, HexapodParams
from hexapod_common.core.topics import stamp_ns

RESYNC_TICKS = 20    # realtime: re-anchor the schedule when this many periods behind
SWITCH_WINDOW = 3    # ticks after a switch whose misses count as caused by it
LATENCY_BIN = 20e-6  # s: histogram of state -> command round trips, bins of 20 us ...
LATENCY_BINS = 2500  # ... up to 50 ms (the last bin collects the rest)
MAX_RANGES = 10000   # tick ranges kept of uncommanded torques
#: Wall s between two looks, while a lockstep tick waits for its command, at whether the
#: nodes it needs are still alive; a tick whose nodes have left is missed after this long.
LIVENESS_LOOK = 0.5
#: Wall s realtime's tick 0 waits for its command (the first messages of every connection
#: are slow) before the schedule starts without it.
FIRST_TICK_WAIT = 0.5

FloatArray = npt.NDArray[np.float64]


class Log(Protocol):
    """Where the machine says what happened (a node's logger)."""

    def info(self, message: str) -> None: ...
    def warning(self, message: str) -> None: ...
    def error(self, message: str) -> None: ...


class Hooks(Protocol):
    """What the shell does at a tick boundary (all called from the machine's step)."""

    def at_boundary(self, tick: int) -> None:
        """After integrating, before switches and parameter changes are applied (the shell
        may request them here: a scripted switch, the local switch channel)."""

    def switched(self, tick: int, old: str, new: str) -> None:
        """The controller in charge changed at ``tick``."""

    def ready(self, tick: int) -> None:
        """Tick ``tick`` is ready to be sampled and published."""


class Wait(Enum):
    """What the shell waits for after publishing a tick."""

    STOP = "stop"              # the run is over
    TIMEOUT = "timeout"        # lockstep: call timeout() at the deadline
    PERIOD_END = "period_end"  # realtime: call period_end() at the deadline


class Outcome(Enum):
    """What became of a command (:meth:`TickMachine.command`)."""

    IGNORED = "ignored"      # the run is over
    AHEAD = "ahead"          # stamped after the current tick: drop it as a bad stamp
    FOREIGN = "foreign"      # from a controller not in charge
    LATE = "late"            # for an earlier tick (realtime: maybe applied at period end)
    STALE = "stale"          # for this tick but already answered, or before the start
    SEND = "send"            # lockstep: applied, the next tick is ready: publish it
    READY = "ready"          # realtime: applied, the next tick waits for its time
    SCHEDULE = "schedule"    # realtime, tick 0 answered: the schedule starts, publish now


class TickMachine:
    """Physics plus the tick rules of the module doc; ``params()`` gives the current values
    (sim.lockstep_timeout, hold_time, fallback_damping may be read at any tick)."""

    def __init__(self, physics: Physics, params: Callable[[], HexapodParams], log: Log,
                 hooks: Hooks, *, stop_at_end: bool = False) -> None:
        p = params()
        self.physics = physics
        self.params = params
        self.log = log
        self.hooks = hooks
        self.mode = p.sim.mode
        self.period = p.sim.control_period
        self.period_ns = int(round(self.period * 1e9))
        self.end_tick = int(round(p.run.duration / self.period))
        self.stop_at_end = stop_at_end
        self.in_charge = p.run.controller
        self.pending_controller: str | None = None
        self.pending_params: HexapodParams | None = None
        self.torque = np.zeros((N_LEGS, 2))
        self.drive: FloatArray | None = None  # the drive command held (None: a torque)
        self.obs = physics.observe()
        self.source = L.COMMANDED  # of the torque acting now
        self.stamp = -1            # stamp of the tick published last
        self.prepared_tick = 0
        self.answered = False
        self.advanced = False  # realtime: the current tick's command applied, next tick ready
        self.newest: FloatArray | None = None  # realtime: newest command not yet applied
        self.newest_stamp = -1  # its stamp (an older late command never replaces it)
        self.started = False
        self.finished = False
        self.missed = self.late = self.on_time = self.foreign = self.resyncs = 0
        # lockstep: ticks that waited past the first look for a living controller, the
        # longest such wait (wall s), and how often the cap (sim.lockstep_timeout) was hit
        self.long_waits = self.cap_hits = 0
        self.longest_wait = 0.0
        self._long_wait_tick = -1
        self.silent_ticks = 0
        # Never log per tick: lockstep warns at the first timeout, realtime after 10 ms.
        self.warn_after = 1 if self.mode == "lockstep" else max(1, round(0.01 / self.period))
        self.warned = False
        self.fallback = False
        self.fallback_episodes = 0
        self.switches = 0
        self.switch_tick = -SWITCH_WINDOW
        self.missed_after_switch = 0
        self.t0 = 0.0
        self.wall_start = 0.0
        self.published_at = 0.0  # wall time the current tick went out
        self.latency = np.zeros(LATENCY_BINS, dtype=np.int64)
        self.not_commanded: list[list[int]] = []  # [a, b) ranges of held or fallback torques
        self.fallback_ranges: list[list[int]] = []
        self.switch_log: list[dict[str, object]] = []

    @property
    def tick(self) -> int:
        """The tick the physics is at (the next to publish)."""
        return int(self.physics.tick)

    # ------------------------------------------------------------------ requests
    def request_switch(self, controller: str) -> None:
        """Hand over to ``controller`` at the next tick boundary."""
        self.pending_controller = controller

    def request_params(self, params: HexapodParams) -> None:
        """Apply live (ground, actuator) parameters at the next tick boundary."""
        self.pending_params = params

    # ------------------------------------------------------------------ publishing
    def start(self, now: float) -> None:
        """The run starts: tick 0 is sampled and sent next."""
        self.started = True
        self.wall_start = self.t0 = now

    def sample(self) -> tuple[int, int, FloatArray, str]:
        """(tick, stamp ns, observation (9, 6, 2), joint_states frame_id) of the current
        tick."""
        k = self.tick
        self.obs = self.physics.observe()
        self.prepared_tick = k
        return k, stamp_ns(k * self.period), self.obs, L.state_frame(self.in_charge, self.source)

    def sending(self, now: float) -> None:
        """The sampled tick goes out now (the round trip counts from here)."""
        self.stamp = stamp_ns(self.prepared_tick * self.period)
        self.answered = False
        self.advanced = False
        self.published_at = now

    def sent(self, now: float) -> tuple[Wait, float]:
        """The sampled tick went out (:meth:`sending`): what to wait for, until when."""
        k = self.prepared_tick
        if self.stop_at_end and k >= self.end_tick:
            self.finished = True
            return Wait.STOP, now
        if self.mode == "lockstep":
            cap = self.params().sim.lockstep_timeout
            wait = self.period if self.silent_ticks else min(LIVENESS_LOOK, cap)
            return Wait.TIMEOUT, now + wait
        if k == 0:
            # Realtime: tick 0 waits a little (the first messages of every connection are
            # slow); the wall-clock schedule starts when its command arrives.
            return Wait.PERIOD_END, now + FIRST_TICK_WAIT
        due = self.t0 + (k + 1) * self.period
        if now - due > RESYNC_TICKS * self.period:
            self.resyncs += 1
            self.t0 = now - k * self.period
            due = now + self.period
        return Wait.PERIOD_END, due

    def release_at(self) -> float:
        """Lockstep: the wall time (monotonic s) the next tick may go out, at most
        ``sim.lockstep_max_rtf`` sim s per wall s counted from the current tick's sending
        (0.0: at once; a graph slower than that is never made to catch up)."""
        rtf = self.params().sim.lockstep_max_rtf
        return self.published_at + self.period / rtf if rtf > 0 else 0.0

    # ------------------------------------------------------------------ inputs
    def command(self, stamp_ns: int, controller: str, effort: FloatArray,
                now: float) -> Outcome:
        """A command (stamp, the controller that sent it, and either the demanded torque
        (12,) or (6, 2), or a drive command (6, 6, 2), see :func:`as_demand`)."""
        if self.finished:
            return Outcome.IGNORED
        if stamp_ns > max(self.stamp, 0):
            return Outcome.AHEAD
        if controller != self.in_charge:
            self.foreign += 1
            return Outcome.FOREIGN
        if stamp_ns != self.stamp or self.answered or not self.started:
            if stamp_ns < self.stamp:
                self.late += 1
                if (self.mode == "realtime" and not self.advanced
                        and stamp_ns > self.newest_stamp):
                    self.newest = as_demand(effort).copy()
                    self.newest_stamp = stamp_ns
                return Outcome.LATE
            return Outcome.STALE
        self.answered = True
        lat = int((now - self.published_at) / LATENCY_BIN)
        self.latency[min(lat, LATENCY_BINS - 1)] += 1
        demand = as_demand(effort)
        if self.silent_ticks:
            self._controller_back()
        if self.mode == "lockstep":
            self._step(demand)
            return Outcome.SEND
        self.on_time += 1
        self.newest = None
        self.newest_stamp = stamp_ns
        self._step(demand)
        self.advanced = True
        if self.tick == 1:  # the schedule starts: tick 1 goes out now
            self.t0 = now - self.period
            return Outcome.SCHEDULE
        return Outcome.READY

    def waiting(self, now: float, alive: bool) -> float | None:
        """Lockstep, at the deadline of :meth:`sent`: whether the current tick waits longer
        for its command. ``alive``: the controller in charge and the nodes its command needs
        are still running (the shell knows). The wall time to look again, or None: the tick
        is missed (call :meth:`timeout`): its nodes have left, the controller was already
        silent, or ``sim.lockstep_timeout`` has passed since the tick went out (said once)."""
        if self.silent_ticks or not alive or self.answered:
            return None
        cap = self.params().sim.lockstep_timeout
        waited = now - self.published_at
        if self._long_wait_tick != self.prepared_tick:
            self._long_wait_tick = self.prepared_tick
            self.long_waits += 1
        self.longest_wait = max(self.longest_wait, waited)
        if waited < cap:
            return min(self.published_at + cap, now + LIVENESS_LOOK)
        self.cap_hits += 1
        self.log.warning(
            f"waited {waited:.1f} s for {self.in_charge}'s command of tick {self.tick} "
            f"while it is alive: sim.lockstep_timeout ({cap:g} s) reached, counting the tick "
            f"missed")
        return None

    def timeout(self) -> None:
        """Lockstep: no command for the current tick in time (then publish the next)."""
        self._miss()
        self._count_silent()
        self._step(None)

    def period_end(self, now: float) -> None:
        """Realtime: the current tick's period is over (then publish the next tick), having
        applied the newest command (held torque or fallback if there is none)."""
        if self.advanced:
            return
        if self.tick == 0:
            self.t0 = now - self.period
        self._miss()
        demand, self.newest = self.newest, None
        if demand is None:
            self._count_silent()
        elif self.silent_ticks:
            self._controller_back()
        self._step(demand)

    # ------------------------------------------------------------------ rules
    def _miss(self) -> None:
        self.missed += 1
        if self.tick - self.switch_tick < SWITCH_WINDOW:
            self.missed_after_switch += 1

    def _count_silent(self) -> None:
        """One more period without any command: hold, then fall back after sim.hold_time."""
        self.silent_ticks += 1
        k = self.tick
        if self.silent_ticks == self.warn_after:
            self.warned = True
            self.log.warning(
                f"no command from {self.in_charge} since tick {k - self.silent_ticks + 1} "
                f"(t = {(k - self.silent_ticks + 1) * self.period:.3f} s): holding the last "
                f"torque")
        p = self.params()
        hold = p.sim.hold_time
        if not self.fallback and self.silent_ticks * self.period >= hold - 1e-12:
            self.fallback = True
            self.fallback_episodes += 1
            self.log.error(
                f"{self.in_charge} silent for {self.silent_ticks} ticks ({hold:g} s): falling "
                f"back to joint damping ({p.sim.fallback_damping:g} N m s/rad) from tick {k}")

    def _controller_back(self) -> None:
        if self.warned:
            self.log.info(
                f"{self.in_charge} answers again at tick {self.tick} after "
                f"{self.silent_ticks} silent ticks"
                + ("; leaving the damping fallback" if self.fallback else ""))
        self.silent_ticks = 0
        self.warned = False
        self.fallback = False

    def _step(self, demand: FloatArray | None) -> None:
        """Apply a command (None: hold it, or damp in fallback), integrate one period,
        apply what changes at the tick boundary, make the next tick ready.

        A torque (6, 2) is saturated and held over the period; a drive command (6, 6, 2)
        is evaluated by the drive at every physics step. Held, the drive keeps its last
        command, its position setpoint moving on with the velocity setpoint (as between
        two commands); a held torque stays as it was."""
        P = self.physics.P
        self.source = L.COMMANDED
        if demand is None and self.started:
            self.source = L.FALLBACK if self.fallback else L.HELD
            _mark(self.not_commanded, self.tick)
            if self.fallback:
                _mark(self.fallback_ranges, self.tick)
        if demand is not None and demand.ndim == 3:
            self.drive = demand
        elif demand is not None:
            self.drive = None
            saturate(demand, P[P_TMAX], self.torque)
        elif self.fallback:
            self.drive = None
            damping = -self.params().sim.fallback_damping * self.obs[O_THV]
            saturate(damping, P[P_TMAX], self.torque)
        elif self.drive is not None:
            self.drive[C_QREF] += self.drive[C_DQREF] * self.period
        # else: hold self.torque, the torque applied over the last period
        tr = _trace.TRACER
        if tr is not None:
            tr.mark(_trace.STEP0, stamp=self.stamp)
        if self.drive is not None:
            self.physics.advance_drive(self.drive)
            self.torque[:] = self.physics.torque
        else:
            self.physics.advance_tick(self.torque)
        if tr is not None:
            tr.mark(_trace.STEP1, stamp=self.stamp)
        self.hooks.at_boundary(self.tick)
        if self.pending_params is not None:
            self.physics.set_params(self.pending_params)
            self.pending_params = None
        if self.pending_controller is not None:
            old, self.in_charge = self.in_charge, self.pending_controller
            self.pending_controller = None
            self.switches += 1
            self.switch_tick = k = self.tick
            self.silent_ticks = 0
            self.warned = self.fallback = False
            self.log.info(f"switched {old} -> {self.in_charge} at tick {k} "
                          f"(t = {k * self.period:.3f} s)")
            self.switch_log.append({"tick": k, "from": old, "to": self.in_charge})
            self.hooks.switched(k, old, self.in_charge)
        self.hooks.ready(self.tick)

    # ------------------------------------------------------------------ reports
    def latency_ms(self, q: float) -> float:
        """Quantile ``q`` of the state -> command round trip (ms, from the histogram)."""
        n = int(self.latency.sum())
        if n == 0:
            return float("nan")
        i = int(np.searchsorted(np.cumsum(self.latency), q * n))
        return (i + 1) * LATENCY_BIN * 1e3

    def summary_doc(self) -> dict[str, Any]:
        """The end summary as a JSON-able dict (ticks, misses, fallbacks, switches, and the
        tick ranges whose torque was not a command of the controller in charge)."""
        return {"tick": self.tick, "end_tick": self.end_tick, "control_period": self.period,
                "mode": self.mode, "started": self.started, "finished": self.finished,
                "controller": self.in_charge, "missed": self.missed, "late": self.late,
                "on_time": self.on_time, "foreign": self.foreign,
                "long_waits": self.long_waits, "longest_wait_s": round(self.longest_wait, 3),
                "cap_hits": self.cap_hits,
                "fallback_episodes": self.fallback_episodes, "switches": self.switch_log,
                "missed_after_switch": self.missed_after_switch,
                "not_commanded_ticks": self.not_commanded,
                "fallback_ticks": self.fallback_ranges}


def as_demand(command: FloatArray) -> FloatArray:
    """A command as the machine applies it: a torque (6, 2) from (12,) or (6, 2) values; a
    drive command (6, 6, 2) from 72 values (rows layout.COMMAND_FIELDS), or its tau_ff
    (6, 2) when every gain is zero (a torque-only command is a torque, bit for bit)."""
    a = np.asarray(command, dtype=float)
    if a.size == N_LEGS * 2:
        return a.reshape(N_LEGS, 2)
    cmd = a.reshape(6, N_LEGS, 2)
    if not (cmd[C_KP].any() or cmd[C_KD].any() or cmd[C_KF].any()):
        torque: FloatArray = cmd[C_TFF]
        return torque
    return cmd


def _mark(ranges: list[list[int]], k: int) -> None:
    """Add tick ``k`` to a list of [a, b) ranges (merged; at most MAX_RANGES kept)."""
    if ranges and ranges[-1][1] == k:
        ranges[-1][1] = k + 1
    elif len(ranges) < MAX_RANGES:
        ranges.append([k, k + 1])


__all__ = [
    "LATENCY_BIN",
    "LATENCY_BINS",
    "RESYNC_TICKS",
    "SWITCH_WINDOW",
    "Hooks",
    "Log",
    "Outcome",
    "TickMachine",
    "Wait",
    "as_demand",
]
