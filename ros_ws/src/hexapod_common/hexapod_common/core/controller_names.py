"""Controller names and the nodes that serve them (ROS-free).

A controller is switched to by its *name*; the sim names the controller in charge in the
frame_id of its ``/hexapod/joint_states`` and the controller signs its commands with the same
frame_id. The naming rule (docs/controllers.md, "Naming"):

* a controller the project's own controller node runs (the engine's controllers,
  :func:`engine_names`: ``pd_p``, ``pd_pf``) is the node ``<name>_controller``;
* any other controller is the node of the same name (``my_controller`` is the node
  ``my_controller``).

So the rule is one-to-one both ways (:func:`node_of`, :func:`name_of`). A name is a ROS node
name (letters, digits, ``_``; a letter first; at most 64 characters), so it never holds the
``/`` that separates the torque source in a state's frame_id (core/labels.py).
"""
from __future__ import annotations

import re

from .errors import ParameterError

#: Suffix of the nodes that run the engine's controllers.
NODE_SUFFIX = "_controller"
_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,63}\Z")
NAME_RULE = "a controller name: a ROS node name (letters, digits and '_', a letter first, " \
            "at most 64 characters)"


def engine_names() -> tuple[str, ...]:
    """The controllers the project's controller node runs (node ``<name>_controller``)."""
    from .params import CONTROLLERS

    return tuple(CONTROLLERS)


def check_name(name: object, what: str = "run.controller") -> str:
    """``name`` if it is a valid controller name; else ParameterError naming ``what``."""
    if not isinstance(name, str) or not _NAME.match(name):
        raise ParameterError(what, name, NAME_RULE)
    return name


def node_of(name: str) -> str:
    """The node that serves controller ``name``."""
    return f"{name}{NODE_SUFFIX}" if name in engine_names() else name


def name_of(node: str) -> str:
    """The controller name served by node ``node`` (inverse of :func:`node_of`)."""
    if node.endswith(NODE_SUFFIX) and node[:-len(NODE_SUFFIX)] in engine_names():
        return node[:-len(NODE_SUFFIX)]
    return node


__all__ = ["NAME_RULE", "NODE_SUFFIX", "check_name", "engine_names", "name_of", "node_of"]
