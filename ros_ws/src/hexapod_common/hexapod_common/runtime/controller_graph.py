"""Which controllers are on the graph (rclpy graph queries; see core/controller_names.py).

A *controller node* is a node (in namespace ``/``) that publishes ``/hexapod/joint_commands``,
or the node of a registered controller (``pd_p_controller``, ``pd_pf_controller``, a plug-in's
node named as it), which is one in every lifecycle state: unconfigured, it has no publisher.
Its controller name follows the naming rule of core/controller_names.py. Asked by node (tens
of microseconds), not by topic.
"""
from __future__ import annotations

from rclpy.node import Node, NodeNameNonExistentError

from ..core import topics as T
from ..core.controller_names import check_name, engine_names, name_of, node_of
from ..core.errors import ParameterError
from ..core.params import controller_names


def controller_nodes(node: Node) -> list[str]:
    """Names of the controller nodes of the graph (the nodes of registered controllers, and
    the nodes that publish the command topic), sorted."""
    registered = {node_of(c) for c in controller_names()}
    out = []
    for name, ns in node.get_node_names_and_namespaces():
        if ns not in ("/", ""):
            continue
        if name in registered:
            out.append(name)
            continue
        try:
            pubs = node.get_publisher_names_and_types_by_node(name, ns)
        except NodeNameNonExistentError:
            continue
        if any(t == T.JOINT_COMMANDS for t, _ in pubs):
            out.append(name)
    return sorted(set(out))


def controllers_on_graph(node: Node) -> list[str]:
    """The controller names (naming rule) of :func:`controller_nodes` (a node named as a
    built-in controller serves none: left out)."""
    return [c for c in map(name_of, controller_nodes(node)) if c is not None]


class NamesOnGraph(tuple[str, ...]):
    """``name in NamesOnGraph(node)``: ``name`` is a controller name (the naming rule) that
    is built in or whose node is on the graph; with ``on_graph=False``, any controller
    name (for checks written as ``text in allowed``, e.g. the input guard's)."""

    node: Node
    on_graph: bool

    def __new__(cls, node: Node, on_graph: bool = True) -> NamesOnGraph:
        what = "a controller on the graph" if on_graph else "a controller name"
        self = super().__new__(cls, (what,))
        self.node = node
        self.on_graph = on_graph
        return self

    def __contains__(self, name: object) -> bool:
        try:
            check_name(name)
        except ParameterError:
            return False
        assert isinstance(name, str)
        return (not self.on_graph or name in engine_names()
                or node_of(name) in self.node.get_node_names())


__all__ = ["NamesOnGraph", "controller_nodes", "controllers_on_graph"]
