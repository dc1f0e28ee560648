"""A node's parameter records on ``/hexapod/parameters`` (see core/param_log.py).

:class:`ParamAnnouncer` publishes, transient-local so that a recorder started later still
gets them, one ``start`` record with every parameter the node owns (in force from tick 0)
and one ``change`` record per accepted runtime change, with the tick it took effect:

* the sim applies changes at the next tick boundary and announces them there
  (``deferred=True`` and :meth:`ParamAnnouncer.flush` with that tick): exact;
* other nodes apply a change at once and announce the tick given by ``next_tick`` (the
  first tick they process after it, e.g. the next state a controller answers).

Records are signed like every other message of the graph (the node's ``guard``): the
recorder keeps only records of the graph's own nodes, so no process on the domain can
forge the parameters a bag says it ran with.
"""
from __future__ import annotations

from typing import Any, Callable

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rclpy.parameter import Parameter

from hexapod_common.runtime import conversions as C
from hexapod_common.core import topics as T
from ..core.param_log import RECORD_NAME, ParamRecord


class ParamAnnouncer:
    """Publish ``node``'s start parameters now and each accepted change later."""

    def __init__(self, node: Node, period_s: float, next_tick: Callable[[], int] = lambda: 0,
                 *, deferred: bool = False) -> None:
        """``period_s``: control period (s), for the stamps; see the module docstring."""
        self.node = node
        self.period = period_s
        self.next_tick = next_tick
        self.deferred = deferred
        self.pending: dict[str, Any] = {}
        self.sent = 0
        self.pub = node.create_publisher(DiagnosticArray, T.PARAMETERS,
                                         C.TOPIC_QOS[T.PARAMETERS].publisher())
        self.guard = node.guard  # type: ignore[attr-defined]  # every graph node has one
        self.signer = self.guard.signer(T.PARAMETERS)
        node.add_post_set_parameters_callback(self._changed)
        values = {name: p.value for name, p in node.get_parameters_by_prefix("").items()}
        # Each node declares only the model parameters it uses (ros_params.USES); the start
        # record also carries the rest of the model parameters it runs with (read from the
        # params file), so any one node's record gives the run's full parameters.
        binding = getattr(node, "binding", None)
        if binding is not None:
            values = {**binding.params.to_flat(), **values}
            binding.say_changes = False  # said by publish(), with the change's tick
        self.log = getattr(node, "log", None) or node.get_logger()
        #: every parameter's value now: a set to the value it has is no change (not logged,
        #: not recorded)
        self.current = dict(values)
        self.publish("start", 0, values)

    def _changed(self, params: list[Parameter]) -> None:
        values = {p.name: p.value for p in params
                  if p.name not in self.current or self.current[p.name] != p.value
                  or type(self.current[p.name]) is not type(p.value)}
        self.current.update(values)
        if not values:
            return
        if self.deferred:
            self.pending.update(values)
        else:
            self.publish("change", max(0, int(self.next_tick())), values)

    def flush(self, tick: int) -> None:
        """Deferred mode: announce the changes accepted since the last flush at ``tick``."""
        if self.pending:
            values, self.pending = self.pending, {}
            self.publish("change", tick, values)

    def publish(self, kind: str, tick: int, values: dict[str, Any]) -> ParamRecord:
        """Publish one record; returns it."""
        stamp = T.stamp_ns(tick * self.period)
        rec = ParamRecord(self.node.get_name(), kind, tick, stamp, values)
        status = C.Status(f"{RECORD_NAME}/{rec.node}", "ok", kind, rec.to_map())
        self.pub.publish(self.guard.signed(self.signer, C.encode_statuses(stamp, [status])))
        self.sent += 1
        if kind == "change":
            self.log.info(f"parameter change at tick {tick} (t = {tick * self.period:.6g} s): "
                          + ", ".join(f"{n} = {v!r}" for n, v in values.items()))
        return rec


__all__ = ["ParamAnnouncer"]
