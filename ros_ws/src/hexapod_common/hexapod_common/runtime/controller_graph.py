"""Which controllers are on the graph (rclpy graph queries; see core/controller_names.py).

A *controller node* is a node that publishes ``/hexapod/joint_commands`` (in namespace
``/``); its controller name follows the naming rule of core/controller_names.py. Asked by
node (tens of microseconds), not by topic.
"""
from __future__ import annotations

from typing import Iterator

from rclpy.node import Node, NodeNameNonExistentError

from ..core import topics as T
from ..core.controller_names import check_name, engine_names, name_of, node_of
from ..core.errors import ParameterError


def controller_nodes(node: Node) -> list[str]:
    """Names of the nodes of the graph that publish the command topic, sorted."""
    out = []
    for name, ns in node.get_node_names_and_namespaces():
        if ns not in ("/", ""):
            continue
        try:
            pubs = node.get_publisher_names_and_types_by_node(name, ns)
        except NodeNameNonExistentError:
            continue
        if any(t == T.JOINT_COMMANDS for t, _ in pubs):
            out.append(name)
    return sorted(set(out))


def controllers_on_graph(node: Node) -> list[str]:
    """The controller names (naming rule) of :func:`controller_nodes`."""
    return [name_of(n) for n in controller_nodes(node)]


class NamesOnGraph(tuple[str, ...]):
    """``name in NamesOnGraph(node)``: ``name`` is an engine controller or its node is on
    the graph (for checks written as ``text in allowed``, e.g. the input guard's)."""

    node: Node

    def __new__(cls, node: Node) -> NamesOnGraph:
        self = super().__new__(cls, ("a controller on the graph",))
        self.node = node
        return self

    def __contains__(self, name: object) -> bool:
        try:
            check_name(name)
        except ParameterError:
            return False
        assert isinstance(name, str)
        return name in engine_names() or node_of(name) in self.node.get_node_names()

    def __iter__(self) -> Iterator[str]:
        return iter(("a controller on the graph",))


__all__ = ["NamesOnGraph", "controller_nodes", "controllers_on_graph"]
