"""The model's parameters as ROS parameters: declare, validate, apply.

One params file configures the whole graph (``--ros-args --params-file``), but each node
declares only the parameters of :data:`~hexapod_common.core.params.SPECS` that it uses
(:data:`USES`), so that a parameter set on a node that does not use it is refused
("parameter not declared") instead of accepted and ignored; the node still reads the
others from the file (validated, not exposed). Each is declared with a
descriptor built from the same table: description with units and allowed values,
``FloatingPointRange``/``IntegerRange`` where both bounds are finite, and ``read_only``
for everything that cannot change while the model runs. Only these change live:
``ground.*``, ``actuator.*``, ``pd_p.*``, ``pd_pf.*``, ``run.controller`` and
``sim.lockstep_timeout``, ``sim.hold_time``, ``sim.fallback_damping``.

Validation is the engine's own (:func:`~hexapod_common.core.params.check_value` for each value,
:func:`~hexapod_common.core.params.from_flat` for the cross-checks, e.g. a reachable gait, which
involve read-only parameters only and so run at start), so
the nodes, the in-process engine and the CLI accept and reject exactly the same values and
say so with the same message: ``parameter 'actuator.t_max' = -5.0 is invalid: allowed float
in (0, inf]``. A rejected runtime change leaves the node's value as it was; a bad value in
the params file at start is reported by :func:`declare_params` as a
:class:`~hexapod_common.core.errors.ParameterError` (the node logs it and exits non-zero).

Numbers are declared with dynamic typing so that ``400`` and ``400.0`` are both accepted, and
stored in the parameter's own type (:func:`~hexapod_common.core.params.as_kind`): a double
parameter set to the integer ``1000000`` (what ``ros2 param set NODE ground.k_y 1000000``
sends), in a params file or at runtime (a pre-set callback converts it before rclpy's checks),
stays a double, ``1000000.0``, in ``ros2 param get``/``describe``/``dump``. At runtime a
string that reads as a number is that number (``ros2 param set`` reads ``1e6`` as the string
``'1e6'``: YAML 1.1); any other string for a number is refused as the wrong type. rclpy still
rejects a value outside a finite descriptor range before our callback sees it, with its own
message that names the parameter, the value and the range. ``T_max = inf`` (ideal actuators)
is written ``.inf`` in a params file (rcl's parser also accepts ``inf``; both are read as
float infinity) and ``-p actuator.t_max:=.inf`` on a command line.
"""
from __future__ import annotations

import math
from typing import Any, Callable

from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                SetParametersResult)
from rclpy.exceptions import (InvalidParameterTypeException, InvalidParameterValueException,
                              ParameterException)
from rclpy.node import Node
from rclpy.parameter import Parameter

from ..core.errors import ParameterError
from ..core.params import (COMMON_NODE_PARAMS, NODE_PARAMS, SPECS, HexapodParams, Spec,
                           as_kind, check_spec, check_value, controller_group,
                           controller_names, from_flat, load_params, nearest,
                           unknown_parameter)

#: Parameters (or groups, with a trailing '.') that may change while the graph runs.
LIVE = ("ground.", "actuator.", "pd_p.", "pd_pf.", "run.controller", "sim.lockstep_timeout",
        "sim.lockstep_max_rtf", "sim.hold_time", "sim.fallback_damping")


#: Model parameters (or groups, with a trailing '.') each node uses and so declares.
USES: dict[str, tuple[str, ...]] = {
    "hexapod_sim": ("robot.", "body.", "ground.", "gait.", "actuator.", "sim.",
                    "run.controller", "run.duration"),
    "trajectory_generator": ("robot.", "gait.", "sim.dt", "sim.control_period"),
    "pd_p_controller": ("robot.leg_length_1", "robot.leg_length_2", "pd_p."),
    "pd_pf_controller": ("robot.leg_length_1", "robot.leg_length_2", "pd_pf."),
    "metrics": ("gait.", "sim.dt", "sim.control_period", "run.eval_cycles"),
    "markers": ("robot.", "sim.control_period"),
}
#: Parameters rcl or rclpy declare themselves, or that a params file may carry for them.
ROS_OWN = ("use_sim_time", "start_type_description_service")


def _matches(name: str, patterns: tuple[str, ...]) -> bool:
    return any(name == p or (p.endswith(".") and name.startswith(p)) for p in patterns)


def used_by(node_name: str) -> list[str]:
    """The model parameters node ``node_name`` declares (all of them for an unknown node; a
    plug-in controller's node, named as the controller (controller_names.node_of): its
    group, the link lengths and the control period)."""
    patterns = USES.get(node_name)
    if patterns is None and node_name in controller_names():
        group = controller_group(node_name)
        patterns = ("robot.leg_length_1", "robot.leg_length_2", "sim.control_period",
                    f"{group}.")
    return [n for n in SPECS if patterns is None or _matches(n, patterns)]


def check_overrides(values: dict[str, Any]) -> None:
    """Raise ParameterError for an override (params file, ``-p``) that no node knows:
    an unknown model parameter or group, or an unknown node parameter (nearest name)."""
    groups = {n.split(".")[0] for n in SPECS}
    own = {n for names_ in NODE_PARAMS.values() for n in names_} | set(COMMON_NODE_PARAMS)
    for name, value in values.items():
        head, dot, _ = name.partition(".")
        if name in SPECS or name in own or name in ROS_OWN or head == "qos_overrides":
            continue
        if head in groups or not dot:
            if not dot and head in groups:
                raise ParameterError(name, value, f"a group of parameters ({name}.<name>: "
                                     f"value), not a value")
            if not dot:
                raise ParameterError(name, value, "a known parameter name"
                                     + nearest(name, sorted(own) + sorted(SPECS)))
            raise unknown_parameter(name, value)
        raise ParameterError(name, value, f"a known group (unknown group '{head}'"
                             + nearest(head, sorted(groups)) + ")")


def is_live(name: str) -> bool:
    """True if ``name`` may change at runtime."""
    return any(name == p or (p.endswith(".") and name.startswith(p)) for p in LIVE)


def descriptor(name: str, spec: Spec) -> ParameterDescriptor:
    """The ROS descriptor of one parameter, from its spec."""
    d = ParameterDescriptor(
        name=name, description=f"{spec.description}; {spec.allowed()}",
        additional_constraints=f"allowed: {spec.allowed()}",
        read_only=not is_live(name), dynamic_typing=True)
    if spec.lo is not None and spec.hi is not None and math.isfinite(spec.hi):
        if spec.kind is int:
            d.integer_range = [IntegerRange(from_value=int(spec.lo), to_value=int(spec.hi),
                                            step=0)]
        else:
            d.floating_point_range = [FloatingPointRange(
                from_value=float(spec.lo), to_value=float(spec.hi), step=0.0)]
    return d


def _override(node: Node, name: str) -> Any:
    overrides = getattr(node, "_parameter_overrides", {})
    param = overrides.get(name)
    return None if param is None else param.value


def declare_params(node: Node, defaults: HexapodParams | None = None,
                   checks: Checks | None = None) -> HexapodParams:
    """Declare the model parameters ``node`` uses (:data:`USES`); return all, validated.

    ``checks`` replaces the table's check of some parameters on this node (the sim's
    ``run.controller`` takes any controller on the graph, not only the engine's); their
    values are kept as checked, beside the cross-checks of the rest.

    Values come from the node's overrides (params file, ``-p``), else from ``defaults``
    (default: the shipped base experiment); the parameters the node does not use are read
    from the overrides too (validated, not declared). Raises ParameterError naming the
    first bad value, or an override that no node knows (nearest known name).
    """
    base = (defaults or load_params()).to_flat()
    overrides = getattr(node, "_parameter_overrides", {})
    check_overrides({n: o.value for n, o in overrides.items()})
    declared = set(used_by(node.get_name()))
    flat: dict[str, Any] = {}
    for name, spec in SPECS.items():
        if name not in declared:
            flat[name] = check_value(name, overrides[name].value) if name in overrides \
                else base[name]
            continue
        # the override (if any) in the parameter's type: rclpy would store it as given
        value = as_kind(name, overrides[name].value) if name in overrides else base[name]
        try:
            value = node.declare_parameter(name, value, descriptor(name, spec),
                                           ignore_override=True).value
        except (InvalidParameterTypeException, InvalidParameterValueException,
                ParameterException) as err:
            # rclpy's descriptor checks fired first: say it in the engine's words.
            bad = _override(node, name)
            check_value(name, bad)
            raise ParameterError(name, bad, f"{spec.allowed()} ({err})") from err
        flat[name] = (checks or {}).get(name, check_value)(name, value)
    own = {n: flat.pop(n) for n in (checks or {}) if n in flat}
    p = from_flat({**flat, **{n: base[n] for n in own}})
    return _with(p, own)


#: Per-parameter checks that replace the table's on one node: (name, value) -> value.
Checks = dict[str, Callable[[str, Any], Any]]


def _with(p: HexapodParams, values: dict[str, Any]) -> HexapodParams:
    """``p`` with dotted ``values`` set (already checked)."""
    groups: dict[str, dict[str, Any]] = {}
    for name, value in values.items():
        group, _, key = name.partition(".")
        groups.setdefault(group, {})[key] = value
    return p.with_checked(groups)


def declare_node_param(node: Node, name: str) -> Any:
    """Declare one of the node's own parameters (:data:`~hexapod_common.core.params.NODE_PARAMS`:
    default, range, meaning) and return its checked value.

    Declared with dynamic typing so that ``3`` is accepted where ``3.0`` is meant; a value
    outside the spec raises ParameterError. Read-only: the nodes read these once at start,
    so a runtime change is refused ("read-only") rather than accepted and ignored.
    """
    table = NODE_PARAMS.get(node.get_name())
    if table is None and node.get_name() in controller_names():  # a plug-in's node
        table = NODE_PARAMS["pd_p_controller"]
    spec = table[name]  # type: ignore[index]
    value = node.declare_parameter(name, spec.default, ParameterDescriptor(
        name=name, description=f"{spec.description}; allowed {spec.allowed()} "
        f"(read at start: read-only)", dynamic_typing=True, read_only=True)).value
    return check_spec(name, spec, value)


def typed(changes: list[Parameter]) -> list[Parameter]:
    """Pre-set callback: each model parameter's new value in that parameter's type, a string
    that reads as a number for a numeric one included (``ros2 param set NODE ground.k_y 1e6``
    sends ``'1e6'``: :func:`~hexapod_common.core.params.as_kind`), before rclpy's descriptor
    checks and ours; other values as they came (a string that is no number is then refused
    with the parameter, the value and the type expected)."""
    out = []
    for p in changes:
        value = as_kind(p.name, p.value, text=True)
        out.append(p if type(value) is type(p.value) else Parameter(p.name, value=value))
    return out


class ParamBinding:
    """Keeps a node's :class:`HexapodParams` in sync with its ROS parameters.

    ``on_change(params, changed_names)`` runs after an accepted change (post-set callback);
    ``check(changes)``, if given, may refuse a change that is valid in itself but cannot be
    honoured now (returns the reason, or None). ``log``: where to say what was accepted or
    refused (default: the node's logger).
    """

    def __init__(self, node: Node, params: HexapodParams,
                 on_change: Callable[[HexapodParams, set[str]], None] | None = None,
                 check: Callable[[list[Parameter]], str | None] | None = None,
                 log: Any = None, checks: Checks | None = None) -> None:
        from .hot_loop import FastLogger

        self.node = node
        self.log = log if log is not None else FastLogger(node.get_logger().name)
        self._validated: tuple[list[Parameter], HexapodParams] | None = None
        self.params = params
        self._on_change = on_change
        self._check = check
        self._checks = checks or {}
        #: Log each accepted change here; a node's ParamAnnouncer turns this off and says
        #: it with the tick the change takes effect at instead (param_topic.py).
        self.say_changes = True
        node.add_pre_set_parameters_callback(typed)
        node.add_on_set_parameters_callback(self._validate)
        node.add_post_set_parameters_callback(self._apply)

    def _merged(self, changes: list[Parameter]) -> HexapodParams:
        """The parameters with ``changes`` applied, validated.

        Every value goes through check_value. The cross-checks of from_flat (control period
        a multiple of dt, reachable gait) involve only geometry, gait and timing, which are
        read-only: a change of live parameters alone is applied to the current (validated)
        parameters directly, which keeps a switch or a ground change in the sim's loop to
        microseconds instead of the ~1 ms the reachability check takes.
        """
        ours = [p for p in changes if p.name in SPECS]
        if all(is_live(p.name) for p in ours):
            groups: dict[str, dict[str, Any]] = {}
            for p in ours:
                group, _, key = p.name.partition(".")
                groups.setdefault(group, {})[key] = self._checks.get(
                    p.name, check_value)(p.name, p.value)
            cur = self.params
            return cur.with_checked(groups)
        flat = self.params.to_flat()
        own = {}
        for p in ours:
            if p.name in self._checks:
                own[p.name] = self._checks[p.name](p.name, p.value)
            else:
                flat[p.name] = check_value(p.name, p.value)
        for name in self._checks:
            if name in flat and name not in own:
                own[name] = flat.pop(name)
        base = load_params().to_flat()
        return _with(from_flat({**flat, **{n: base[n] for n in own}}), own)

    def _validate(self, changes: list[Parameter]) -> SetParametersResult:
        self._validated = None
        try:
            merged = self._merged(changes)
        except ParameterError as err:
            self.log.warning(f"rejected: {err}")
            return SetParametersResult(successful=False, reason=str(err))
        reason = self._check(changes) if self._check is not None else None
        if reason:
            self.log.warning(f"rejected: {reason}")
            return SetParametersResult(successful=False, reason=reason)
        self._validated = (changes, merged)  # rclpy applies these next (post-set callback)
        return SetParametersResult(successful=True)

    def _apply(self, changes: list[Parameter]) -> None:
        names = {p.name for p in changes if p.name in SPECS}
        if not names:
            return
        done, self._validated = self._validated, None
        self.params = done[1] if done is not None and done[0] is changes else self._merged(changes)
        for p in changes:
            if p.name in names and self.say_changes:
                self.log.info(f"parameter {p.name} = {p.value!r}")
        if self._on_change is not None:
            self._on_change(self.params, names)


__all__ = ["LIVE", "ROS_OWN", "USES", "ParamBinding", "check_overrides", "declare_node_param",
           "declare_params", "descriptor", "is_live", "typed", "used_by"]
