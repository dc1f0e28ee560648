"""Lockstep: the sim does not run away from its recorder.

In lockstep the graph runs as fast as its control loop; the recorder is not on that loop
and takes its queues when it gets the CPU (it runs at a lower priority). Its queues, and
the publishers' histories behind them (``topics.HISTORY_DEPTH`` ticks), absorb a lag;
beyond that the oldest messages are lost to the bag. So the recorder says how far it has
written (``/hexapod/recorded``: the stamp of its newest joint state, every
``topics.RECORDED_EVERY`` ticks) and the sim holds a tick while the recorder is more than
``topics.RECORDER_LAG`` ticks behind it. When the writers of that progress change during a
hold (a recorder closed, or dropped by its peers when its lease ran out; or one joined,
which records nothing while the sim holds), or when the recorder is silent for
``patience`` wall s (stuck; while its process is alive, up to a longer cap: a stopped or
starved recorder is waited for), nobody is waited for until a recorder speaks again. Realtime
runs keep their clock and never hold.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass


@dataclass
class RecorderPace:
    """When the next tick may go out, given the recorder's progress (wall s: monotonic)."""

    #: Ticks the recorder may be behind the tick about to be sent.
    lag: int
    #: Wall s of silence from the recorder after which the sim goes on without it.
    patience: float
    #: The newest tick the recorder said it wrote (None: not heard, or given up on).
    recorded: int | None = None
    #: When the recorder was last heard.
    heard_at: float = 0.0
    #: Holds so far, their total wall s, and how often the sim gave up waiting.
    holds: int = 0
    held_s: float = 0.0
    gave_up: int = 0
    #: Holds ended because the recorder had left the graph (``alive()`` said so).
    left: int = 0
    _since: float | None = None

    def heard(self, tick: int, now: float, current: int) -> None:
        """The recorder wrote tick ``tick`` (its newest joint state); the sim is at tick
        ``current``. A tick past ``current`` counts as ``current``: a stamp far ahead (a key
        holder's) must not end the pacing, which then holds again ``lag`` ticks later."""
        tick = min(tick, current)
        self.recorded = tick if self.recorded is None else max(self.recorded, tick)
        self.heard_at = now

    def behind(self, tick: int) -> bool:
        """Whether ``tick`` would be held: the recorder was heard and is more than ``lag``
        ticks behind it."""
        return self.recorded is not None and tick - self.recorded > self.lag

    def hold_until(self, tick: int, now: float, alive: Callable[[], bool] | None = None,
                   cap: float = 0.0) -> float | None:
        """None: ``tick`` may go out now. Else it is held: look again when the recorder is
        heard or at the returned time (when the sim gives up waiting). ``alive()`` (asked
        once it has been silent for ``patience``): whether the recorder is still on the
        graph; if so its silence is borne up to ``cap`` wall s, if not the hold ends as for
        a recorder that left (:meth:`forget`, counted in :attr:`left`)."""
        if not self.behind(tick):
            self._release(now)
            return None
        patience = self.patience
        if alive is not None and now >= self.heard_at + patience:
            if not alive():  # it has left the graph: nobody to wait for, nothing given up
                self.left += 1
                self.forget(now)
                return None
            patience = max(cap, patience)
        give_up_at = self.heard_at + patience
        if now >= give_up_at:
            self.gave_up += 1
            self.recorded = None  # until the recorder speaks again
            self._release(now)
            return None
        if self._since is None:
            self._since = now
            self.holds += 1
        return give_up_at

    def forget(self, now: float) -> None:
        """The recorders on the graph changed: no tick waits until one speaks again."""
        self.recorded = None
        self._release(now)

    @property
    def holding(self) -> bool:
        """Whether a tick is held now."""
        return self._since is not None

    def _release(self, now: float) -> None:
        if self._since is not None:
            self.held_s += now - self._since
            self._since = None

    def as_dict(self) -> dict[str, float | int]:
        """The summary's figures."""
        return {"recorder_holds": self.holds, "recorder_held_s": round(self.held_s, 3),
                "recorder_given_up": self.gave_up}


__all__ = ["RecorderPace"]
