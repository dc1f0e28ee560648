"""Controller names and the nodes that serve them (ROS-free): the one naming rule.

A controller is switched to by its *name*; the sim names the controller in charge in the
frame_id of its ``/hexapod/joint_states`` and the controller signs its commands with the same
frame_id. The rule (docs/controllers.md, "Naming"), used by the sim (switch, run.controller),
``hexapod status`` and ``hexapod switch``, the recorder and the launcher alike:

* a built-in controller (:data:`ENGINE_CONTROLLERS`: ``pd_p``, ``pd_pf``) is served by the
  node ``<name>_controller``: the project's controller node, or any node that joins under
  that name in its place (``run_graph.sh --no-builtin pd_p`` leaves the place free);
* a node named as a built-in controller itself (``pd_p``) serves no controller: that name
  is the built-in's, and its node is ``pd_p_controller`` (:func:`name_of` gives None,
  :func:`reserved_hint` says how to take the place);
* any other controller is the node of the same name (``my_controller`` is the node
  ``my_controller``).

So :func:`node_of` and :func:`name_of` are inverse on every node that serves a controller. A
name is a ROS node name (letters, digits, ``_``; a letter first; at most 64 characters), so
it never holds the ``/`` that separates the torque source in a state's frame_id
(core/labels.py).
"""
from __future__ import annotations

import re

from .errors import ParameterError

#: The built-in controllers with a compiled law, run by the project's controller node as the
#: nodes ``<name>_controller`` (params.CONTROLLERS is this tuple).
ENGINE_CONTROLLERS = ("pd_p", "pd_pf")
#: Suffix of the nodes that serve the built-in controllers.
NODE_SUFFIX = "_controller"
_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,63}\Z")
NAME_RULE = "a controller name: a ROS node name (letters, digits and '_', a letter first, " \
            "at most 64 characters)"


def engine_names() -> tuple[str, ...]:
    """The built-in controllers (node ``<name>_controller``)."""
    return ENGINE_CONTROLLERS


def check_name(name: object, what: str = "run.controller") -> str:
    """``name`` if it is a valid controller name; else ParameterError naming ``what``.

    The node of a built-in controller (``pd_pf_controller``) is not a controller name: that
    node serves ``pd_pf`` and answers only to that name (a switch to its node's name would
    leave the graph without commands), so the error names the controller to use."""
    if not isinstance(name, str) or not _NAME.match(name):
        raise ParameterError(what, name, NAME_RULE)
    served = name_of(name)
    if served is not None and served != name:
        raise ParameterError(what, name, f"a controller name, not a node's: {name} is the "
                                         f"node of controller {served} (use {served})")
    return name


def node_of(name: str) -> str:
    """The node that serves controller ``name``."""
    return f"{name}{NODE_SUFFIX}" if name in ENGINE_CONTROLLERS else name


def name_of(node: str) -> str | None:
    """The controller served by node ``node`` (inverse of :func:`node_of`); None for a node
    named as a built-in controller (``pd_p``: that controller's node is ``pd_p_controller``)."""
    if node.endswith(NODE_SUFFIX) and node[:-len(NODE_SUFFIX)] in ENGINE_CONTROLLERS:
        return node[:-len(NODE_SUFFIX)]
    return None if node in ENGINE_CONTROLLERS else node


def reserved_hint(node: str) -> str:
    """Why node ``node`` serves no controller ('' if it serves one)."""
    if name_of(node) is not None:
        return ""
    return (f"node {node} serves no controller: {node} is a built-in controller's name, "
            f"served by the node {node_of(node)} (a node takes its place under that name, "
            f"with run_graph.sh --no-builtin {node})")


__all__ = ["ENGINE_CONTROLLERS", "NAME_RULE", "NODE_SUFFIX", "check_name", "engine_names",
           "name_of", "node_of", "reserved_hint"]
