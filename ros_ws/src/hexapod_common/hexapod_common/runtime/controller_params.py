"""A controller's own parameters, read through its standard parameter services.

When a controller that the engine does not know takes over (a node that joined the graph,
docs/controllers.md), the sim asks that node for every parameter it declared
(``list_parameters``, then ``get_parameters``) and records them, with the tick it took over,
as a ``controller`` parameter record (core/param_log.py) in the bag: ``hexapod analyze``
scores its segment under that name and shows those values. Asynchronous: :meth:`poll` moves
the pending reads on (the sim calls it between ticks while any is pending); a node that does
not answer within READ_TIMEOUT s is recorded with no values, and the log says so.
"""
from __future__ import annotations

import time
from typing import Any, Callable

from rclpy.node import Node
from rclpy.parameter import parameter_value_to_python

from ..core.controller_names import node_of

#: Wall s a read may take before it is given up (recorded empty). Asynchronous, so it holds
#: up no tick: generous, as a client made at a switch must first discover the node's
#: services (seconds on a loaded machine).
READ_TIMEOUT = 20.0


class _Read:
    def __init__(self, controller: str, tick: int, until: float) -> None:
        self.controller = controller
        self.tick = tick
        self.until = until
        self.names_future: Any = None
        self.values_future: Any = None
        self.names: list[str] = []


class ControllerParamsReader:
    """Reads controllers' parameters; ``done(controller, tick, values)`` gets each result."""

    def __init__(self, node: Node, loop: Any,
                 done: Callable[[str, int, dict[str, Any]], None]) -> None:
        self.node = node
        self.loop = loop
        self.done = done
        self.clients: dict[str, tuple[Any, Any]] = {}
        self.reads: list[_Read] = []

    @property
    def pending(self) -> bool:
        """Whether a read is under way."""
        return bool(self.reads)

    def _clients(self, target: str) -> tuple[Any, Any]:
        from rcl_interfaces.srv import GetParameters, ListParameters

        got = self.clients.get(target)
        if got is None:
            got = self.clients[target] = (
                self.node.create_client(ListParameters, f"/{target}/list_parameters"),
                self.node.create_client(GetParameters, f"/{target}/get_parameters"))
            self.loop.refresh()
        return got

    def prepare(self, controller: str) -> None:
        """Make the service clients for ``controller`` now (at the switch request), so that
        their discovery runs while the switch waits for its tick boundary."""
        self._clients(node_of(controller))

    def read(self, controller: str, tick: int) -> None:
        """Start reading ``controller``'s parameters for the record of ``tick``."""
        self._clients(node_of(controller))
        self.reads.append(_Read(controller, tick, time.monotonic() + READ_TIMEOUT))

    def poll(self) -> None:
        """Move the pending reads on; report the finished ones."""
        from rcl_interfaces.srv import GetParameters, ListParameters

        left = []
        for r in self.reads:
            lister, getter = self._clients(node_of(r.controller))
            if r.names_future is None:
                if lister.service_is_ready():
                    r.names_future = lister.call_async(ListParameters.Request())
            elif r.values_future is None and r.names_future.done():
                res = r.names_future.result()
                r.names = sorted(res.result.names) if res is not None else []
                r.values_future = getter.call_async(GetParameters.Request(names=r.names))
            elif r.values_future is not None and r.values_future.done():
                res = r.values_future.result()
                values = ({} if res is None else
                          {n: parameter_value_to_python(v) for n, v in zip(r.names, res.values)})
                self.done(r.controller, r.tick, values)
                continue
            if time.monotonic() > r.until:
                self.done(r.controller, r.tick, {})
                continue
            left.append(r)
        self.reads = left


__all__ = ["READ_TIMEOUT", "ControllerParamsReader"]
