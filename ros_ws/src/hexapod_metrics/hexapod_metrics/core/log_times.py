"""Log times of the recorded messages: each message's own simulated time (ns).

* Stamped messages (JointStates, Clock, DiagnosticArrays) carry it in their header.
* ``visualization_msgs/MarkerArray`` has no header of its own: its first marker's stamp
  (the markers node stamps every marker with the tick it draws).
* ``std_msgs/String`` on ``/hexapod/active_controller`` has no stamp at all: it is logged at
  the tick the switch took effect, i.e. the first ``/hexapod/joint_states`` whose
  ``frame_id`` (the controller in charge) names it. :class:`ControllerLogTimes` pairs the
  two, whichever arrives first.
"""
from __future__ import annotations

import struct
from typing import NamedTuple

__all__ = ['ControllerLogTimes', 'marker_array_stamp']

_NS = 1_000_000_000
_STAMP = struct.Struct('<iI')
_U32 = struct.Struct('<I')


def marker_array_stamp(data: bytes) -> int | None:
    """Stamp (ns) of the first marker of a serialized MarkerArray; None if it has none."""
    if len(data) < 16 or _U32.unpack_from(data, 4)[0] == 0:
        return None
    sec, nsec = _STAMP.unpack_from(data, 8)  # the first Marker's header.stamp
    return int(sec) * _NS + int(nsec)


class _Waiting(NamedTuple):
    controller: str
    data: bytes
    since: int
    """Newest state stamp when the message came in (ns)."""


class ControllerLogTimes:
    """Pairs ``/hexapod/active_controller`` messages with the tick their switch took effect.

    Feed every joint_states stamp and frame_id to :meth:`on_state` and every controller
    message to :meth:`on_controller`; both return the (log time, message) pairs ready to be
    written. A message whose controller never shows up in the states within ``patience_ns``
    of simulated time (a refused switch, say) is logged at the newest state's stamp;
    :meth:`flush` returns those still waiting (at close).
    """

    def __init__(self, patience_ns: int = _NS) -> None:
        """``patience_ns``: how long a message waits for its controller to take over."""
        self.patience = int(patience_ns)
        self.frame: str | None = None
        self.change = -1  # stamp where the states' frame_id last changed
        self.claimed = True  # that change was already paired with a message
        self.latest = -1
        self.waiting: list[_Waiting] = []
        self.unmatched = 0
        """Messages logged at the newest stamp because their controller never took over."""

    def on_state(self, stamp_ns: int, frame_id: str) -> list[tuple[int, bytes]]:
        """A joint_states message: its stamp (ns) and frame_id."""
        if stamp_ns > self.latest:
            self.latest = stamp_ns
        if frame_id != self.frame:
            self.frame, self.change, self.claimed = frame_id, stamp_ns, False
        out: list[tuple[int, bytes]] = []
        keep: list[_Waiting] = []
        for w in self.waiting:
            if not self.claimed and w.controller == frame_id:
                out.append((self.change, w.data))
                self.claimed = True
            elif self.latest - w.since > self.patience:
                out.append((self.latest, w.data))
                self.unmatched += 1
            else:
                keep.append(w)
        self.waiting = keep
        return out

    def on_controller(self, controller: str, data: bytes) -> list[tuple[int, bytes]]:
        """An active_controller message naming ``controller`` (its serialized ``data``)."""
        if not self.claimed and controller == self.frame:
            self.claimed = True
            return [(self.change, data)]
        self.waiting.append(_Waiting(controller, data, self.latest))
        return []

    def flush(self) -> list[tuple[int, bytes]]:
        """The messages still waiting, at the newest stamp seen (at least 0)."""
        out = [(max(self.latest, 0), w.data) for w in self.waiting]
        self.unmatched += len(out)
        self.waiting = []
        return out
