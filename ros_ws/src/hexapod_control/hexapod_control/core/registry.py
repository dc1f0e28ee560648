"""The controller registry: any controller by name, the built-ins like a user's.

Names come from the Python entry points of the group ``hexapod.controllers``
(``pd_p``, ``pd_pf`` and ``pd_alpha`` are declared in this package's setup.py); a
``module:Class`` path loads a class for a quick trial. An unknown name raises a one-line
ParameterError that lists the registered names.
"""
from __future__ import annotations

from dataclasses import fields
from typing import Any, NamedTuple

from hexapod_common.core.errors import ParameterError
from hexapod_common.core.params import (HexapodParams, Spec, controller_group,
                                        controller_names, load_controller_class)

from .controller_api import Context


class ParamInfo(NamedTuple):
    """One parameter of a controller: dotted name, type, default, allowed range, meaning."""

    name: str
    kind: str
    default: Any
    allowed: str
    description: str


def names() -> tuple[str, ...]:
    """Registered controller names, sorted."""
    return controller_names()


def load(name: str) -> type[Any]:
    """The controller class of ``name`` (a registered name or module:Class); ParameterError
    if it lacks the contract's ``Params``, ``reset()`` or ``law(obs)``."""
    cls = load_controller_class(name)
    missing = [m for m in ("reset", "law") if not callable(getattr(cls, m, None))]
    if missing:
        raise ParameterError("run.controller", name, "a controller class with Params, reset() "
                             "and law(obs) (hexapod_control.core.controller_api); "
                             f"{cls.__name__} lacks " + ", ".join(f"{m}()" for m in missing))
    return cls


def create(name: str, p: HexapodParams) -> Any:
    """An instance of controller ``name`` with its parameters from ``p``, reset."""
    cls = load(name)
    ctx = Context(p.sim.control_period, p.robot.leg_length_1, p.robot.leg_length_2)
    ctrl = cls(p.gains(name), ctx)
    ctrl.reset()
    return ctrl


def is_compiled(name: str, p: HexapodParams) -> bool:
    """True if ``name`` runs on the compiled torque-only fast path with parameters ``p``."""
    cls = load(name)
    if getattr(cls, "compiled_code", None) is None:
        return False
    return bool(create(name, p).torque_only)


def describe(name: str, p: HexapodParams | None = None) -> list[ParamInfo]:
    """The parameters of controller ``name``: defaults from ``p`` (the params file) where
    given, else the spec table's."""
    cls = load(name)
    group = controller_group(name)
    values = p.gains(name) if p is not None else None
    out = []
    for f in fields(cls.Params):
        spec: Spec = f.metadata["spec"]
        default = getattr(values, f.name) if values is not None else spec.default
        out.append(ParamInfo(f"{group}.{f.name}", spec.kind.__name__, default, spec.allowed(),
                             spec.description))
    return out


__all__ = ["ParamInfo", "create", "describe", "is_compiled", "load", "names"]
