"""Parameters: one frozen dataclass per group, one table of ranges, one validator, one loader.

The YAML file is a ROS 2 params file (``/**: ros__parameters: <group>: <name>: value``);
nested keys become dotted ROS parameter names (``ground.k_y``). The same table
(:data:`SPECS`) gives the ROS nodes their parameter descriptors, so the nodes, the
engine and the CLI accept and reject exactly the same values.

Units are SI throughout (m, kg, s, N, N·m). Defaults are the paper's base experiment
(model.md, "Experiments", E1).

Controller groups (``pd_p``, ``pd_pf``, ``pd_alpha``, a user's) are not fixed here: each
registered controller (entry point group ``hexapod.controllers``) brings its own table, the
fields of its ``Params`` dataclass, read on first use of :data:`SPECS`. A module:Class
controller's group is its class attribute ``name`` (default: the class name in lower case),
known once the class is loaded (:func:`load_controller_class`). A controller parameter
missing from a params file takes its spec's default when it has one.
"""
from __future__ import annotations

import difflib
import importlib
import importlib.metadata
import math
import os
import re
from dataclasses import dataclass, field, fields, replace
from functools import lru_cache
from pathlib import Path
from types import MappingProxyType
from typing import Any, Mapping

import yaml

from .controller_names import ENGINE_CONTROLLERS
from .errors import ParameterError, ParamsFileError
from .robot import N_LEGS

#: The built-in controllers with a compiled law (the ROS graph's controller nodes). Every
#: registered controller (:func:`controller_names`) is accepted by ``run.controller``.
CONTROLLERS = ENGINE_CONTROLLERS
#: Python entry-point group of controller plug-ins (``name = module:Class``).
CONTROLLER_GROUP = "hexapod.controllers"
MODES = ("lockstep", "realtime")
INTEGRATORS = ("implicit_ground_damping", "semi_implicit_euler")


@dataclass(frozen=True)
class Spec:
    """Type, range and meaning of one parameter."""

    kind: type
    description: str
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False
    choices: tuple[str, ...] = ()
    allow_inf: bool = False
    default: Any = None  # node parameters only (model parameters: the params file)

    def allowed(self) -> str:
        """Human text of the allowed values, used in error messages and descriptors."""
        if self.kind is bool:
            return "true or false"
        if self.choices:
            return "one of " + ", ".join(c or "''" for c in self.choices)
        if self.lo is None and self.hi is None:
            return f"any {self.kind.__name__}"
        lo = "-inf" if self.lo is None else f"{self.lo:g}"
        hi = "inf" if self.hi is None else f"{self.hi:g}"
        left = "(" if self.lo_open or self.lo is None else "["
        right = ")" if (self.hi_open or self.hi is None) and not self.allow_inf else "]"
        if self.allow_inf:
            hi = "inf"
        return f"{self.kind.__name__} in {left}{lo}, {hi}{right}"


def _f(desc: str, lo: float | None = None, hi: float | None = None, *, lo_open: bool = False,
       hi_open: bool = False, allow_inf: bool = False) -> Any:
    return field(metadata={"spec": Spec(float, desc, lo, hi, lo_open, hi_open, (), allow_inf)})


def _i(desc: str, lo: int, hi: int) -> Any:
    return field(metadata={"spec": Spec(int, desc, lo, hi)})


def _s(desc: str, choices: tuple[str, ...]) -> Any:
    return field(metadata={"spec": Spec(str, desc, choices=choices)})


@dataclass(frozen=True)
class RobotParams:
    """Geometry and masses (model.md "Masses": point masses at hip, knee and foot)."""

    leg_length_1: float = _f("thigh length L_i1 (m)", 0.0, 100.0, lo_open=True)
    leg_length_2: float = _f("shank length L_i2 (m)", 0.0, 100.0, lo_open=True)
    mass_1: float = _f("thigh mass M_i1, a point mass at the knee (kg)", 0.0, 1e4, lo_open=True)
    mass_2: float = _f("shank mass M_i2, a point mass at the foot (kg)", 0.0, 1e4, lo_open=True)
    body_mass: float = _f("body mass M_b, split into 6 hip point masses (kg)", 0.0, 1e5,
                          lo_open=True)
    stroke_pitch: float = _f("stroke pitch S_P between leg pairs (m)", 0.0, 100.0)
    foot_offset: float = _f("foot trajectory offset O_i (m)", -100.0, 100.0)


@dataclass(frozen=True)
class SpringDashpot:
    """Linear spring-dashpots along x and y (the body's and the ground's; model.md "Body
    compliance", "Ground contact"): F = -K d - B v per axis."""

    k_x: float = _f("stiffness K_x (N/m)", 0.0, 1e12)
    k_y: float = _f("stiffness K_y (N/m)", 0.0, 1e12)
    b_x: float = _f("damping B_x (N s/m)", 0.0, 1e12)
    b_y: float = _f("damping B_y (N s/m)", 0.0, 1e12)


@dataclass(frozen=True)
class BodyParams(SpringDashpot):
    """Spring-dashpots between body segments (model.md "Body compliance")."""


@dataclass(frozen=True)
class GroundParams(SpringDashpot):
    """Foot-ground spring-dashpot (model.md "Ground contact") at 100 %; effective values:
    base x scale."""

    scale: float = _f("factor on all four ground parameters (1.0 = 100 %, the sweep variable)",
                      0.0, 1e6, lo_open=True)
    friction_mu: float = _f("Coulomb limit |F_x| <= mu F_y; 0 disables it (paper: none)",
                            0.0, 100.0)


@dataclass(frozen=True)
class GaitParams:
    """Wave gait and trajectory (paper eqs. 1-4)."""

    duty_factor: float = _f("duty factor beta", 0.0, 1.0, lo_open=True, hi_open=True)
    step_length: float = _f("step length L_S (m)", 0.0, 100.0, lo_open=True)
    body_height: float = _f("body (hip) height H_B (m)", 0.0, 100.0, lo_open=True)
    foot_clearance: float = _f("maximum foot clearance F_C (m)", 0.0, 100.0)
    velocity: float = _f("forward body velocity V_F (m/s)", 0.0, 100.0, lo_open=True)


@dataclass(frozen=True)
class ActuatorParams:
    """Joint actuators (paper eq. 6)."""

    t_max: float = _f("torque saturation T_max (N m); .inf = ideal actuator", 0.0, None,
                      lo_open=True, allow_inf=True)


@dataclass(frozen=True)
class GainParams:
    """G_c1 = Kp + Kd s per joint and the inner gain K_f (paper eq. 7, Table I)."""

    kp1: float = _f("hip joint proportional gain Kp_1 (N m/rad)", 0.0, 1e9)
    kd1: float = _f("hip joint derivative gain Kd_1 (N m s/rad)", 0.0, 1e9)
    kp2: float = _f("knee joint proportional gain Kp_2 (N m/rad)", 0.0, 1e9)
    kd2: float = _f("knee joint derivative gain Kd_2 (N m s/rad)", 0.0, 1e9)
    kf: float = _f("inner loop gain K_f (G_c2)", 0.0, 100.0)

    def as_tuple(self) -> tuple[float, float, float, float, float]:
        """(Kp1, Kd1, Kp2, Kd2, K_f)."""
        return (self.kp1, self.kd1, self.kp2, self.kd2, self.kf)


@dataclass(frozen=True)
class SimParams:
    """Integration, control rate and graph timing."""

    dt: float = _f("physics step (s)", 0.0, 0.01, lo_open=True)
    integrator: str = _s("semi_implicit_euler as model.md; implicit_ground_damping (default) "
                         "also takes the ground dampers at the end-of-step velocity", INTEGRATORS)
    control_period: float = _f("control period, a multiple of dt (s)", 0.0, 0.1, lo_open=True)
    mode: str = _s("graph mode", MODES)
    lockstep_timeout: float = _f("lockstep: most wall time a tick waits for the command of a "
                                 "controller that is alive (s; one whose node has left: "
                                 "0.5 s), then a missed tick", 0.0, 3600.0, lo_open=True)
    lockstep_max_rtf: float = _f("lockstep: at most this many sim s per wall s, e.g. 1 to "
                                 "watch a run at real time (0: as fast as the graph goes)",
                                 0.0, 1e6)
    hold_time: float = _f("controller silent this long (sim s): hold the last torque, then "
                          "fall back to joint damping", 0.0, 10.0, lo_open=True)
    fallback_damping: float = _f("joint damping of the safe fallback (N m s/rad)", 0.0, 1e6)


@dataclass(frozen=True)
class RunParams:
    """What one run does."""

    controller: str = field(metadata={"spec": Spec(
        str, "controller in charge: a registered name (`hexapod controllers`) or "
        "module:Class")})
    duration: float = _f("simulated duration (s); 0: until stopped (a graph run of "
                         "run_graph.sh --duration 0; the engine needs at least "
                         "run.eval_cycles gait cycles)", 0.0, 1e6)
    eval_cycles: int = _i("gait cycles at the end of the run that the indices cover", 1, 1000)


#: The model's own groups, in their listing order (controller groups go before "sim").
_MODEL_GROUPS: dict[str, type] = {
    "robot": RobotParams, "body": BodyParams, "ground": GroundParams, "gait": GaitParams,
    "actuator": ActuatorParams, "sim": SimParams, "run": RunParams,
}
#: Controller groups: name -> the controller's parameter dataclass (its spec table), filled
#: from the registered controllers (:func:`register_controller_group`, entry points).
_CONTROLLER_GROUPS: dict[str, type] = {}
#: module:Class paths -> the group name their class declares.
_CONTROLLER_ALIASES: dict[str, str] = {}


class _GroupTypes(dict[str, type]):
    """Group name -> dataclass, model groups and controller groups in listing order; reads
    the registered controllers on first use."""

    def _all(self) -> dict[str, type]:
        _discover()
        ctrl = sorted(_CONTROLLER_GROUPS, key=lambda n: (n not in CONTROLLERS, n))
        out = {k: v for k, v in _MODEL_GROUPS.items() if k != "sim" and k != "run"}
        out.update((n, _CONTROLLER_GROUPS[n]) for n in ctrl)
        out["sim"], out["run"] = _MODEL_GROUPS["sim"], _MODEL_GROUPS["run"]
        return out

    def __getitem__(self, key: str) -> type:
        return self._all()[key]

    def __contains__(self, key: object) -> bool:
        return key in self._all()

    def __iter__(self) -> Any:
        return iter(self._all())

    def __len__(self) -> int:
        return len(self._all())

    def get(self, key: str, default: Any = None) -> Any:
        return self._all().get(key, default)

    def items(self) -> Any:
        return self._all().items()

    def keys(self) -> Any:
        return self._all().keys()

    def values(self) -> Any:
        return self._all().values()


_GROUP_TYPES = _GroupTypes()
_discovering = False
_discovered = False


def registered_controllers() -> dict[str, importlib.metadata.EntryPoint]:
    """Controller name -> its entry point in the group :data:`CONTROLLER_GROUP` (nothing is
    imported; read once per process)."""
    return dict(_entry_points())


@lru_cache(maxsize=1)
def _entry_points() -> tuple[tuple[str, importlib.metadata.EntryPoint], ...]:
    return tuple((ep.name, ep) for ep in importlib.metadata.entry_points(group=CONTROLLER_GROUP))


def controller_names() -> tuple[str, ...]:
    """Names of the registered controllers, sorted (built-ins included)."""
    return tuple(sorted(set(registered_controllers()) | set(_CONTROLLER_GROUPS)))


def register_controller_group(name: str, params_type: type, alias: str | None = None) -> None:
    """Make ``name.*`` parameters (the fields of the dataclass ``params_type``, each with a
    :class:`Spec` in its metadata) known; ``alias``: a module:Class path naming the same
    controller."""
    if _CONTROLLER_GROUPS.get(name) is params_type and (
            not alias or _CONTROLLER_ALIASES.get(alias) == name):
        return  # known already (every run loads its controllers: no spec table rebuild)
    for f in fields(params_type):
        if not isinstance(f.metadata.get("spec"), Spec):
            raise TypeError(f"controller {name!r}: parameter {f.name!r} of "
                            f"{params_type.__name__} has no Spec (use controller_api.param)")
        _settle_kind(name, f)
    if _CONTROLLER_GROUPS.get(name, params_type) is not params_type:
        raise ParameterError("run.controller", name, "one class per controller name "
                             f"({name!r} is already {_CONTROLLER_GROUPS[name].__name__}'s)")
    _CONTROLLER_GROUPS[name] = params_type
    if alias:
        _CONTROLLER_ALIASES[alias] = name
    SPECS.refresh()


#: Field metadata key: the Spec's kind was not given (controller_api.param), so it is the
#: field's annotation, settled at registration (:func:`_settle_kind`).
KIND_INFERRED = "kind_inferred"
_KINDS = {"float": float, "int": int, "bool": bool, "str": str}


def _settle_kind(controller: str, f: Any) -> None:
    """Give a controller parameter declared without ``kind`` its annotation's kind
    (``warmup: int``: whole numbers only) and check its default against it (TypeError,
    one line, naming the controller and the parameter)."""
    spec: Spec = f.metadata["spec"]
    if f.metadata.get(KIND_INFERRED):
        annotation = f.type if isinstance(f.type, str) else getattr(f.type, "__name__", "")
        kind = _KINDS.get(annotation, spec.kind)
        if kind is not spec.kind:
            spec = replace(spec, kind=kind)
            f.metadata = MappingProxyType({**f.metadata, "spec": spec, KIND_INFERRED: False})
    try:
        if spec.default is not None:  # the built-ins' come from the params file
            check_spec(f"{controller}.{f.name}", spec, spec.default)
    except ParameterError as err:
        raise TypeError(f"controller {controller!r}: the default of parameter {f.name!r} "
                        f"does not fit it: {err}") from None


def unregister_controller_group(name: str) -> None:
    """Forget a group that :func:`register_controller_group` made known (a module:Class
    controller this process loaded; entry points are found again on the next use)."""
    _CONTROLLER_GROUPS.pop(name, None)
    for alias in [a for a, n in _CONTROLLER_ALIASES.items() if n == name]:
        del _CONTROLLER_ALIASES[alias]
    SPECS.refresh()


def load_controller_class(name: str) -> type:
    """The class of the controller ``name``: a registered name or a module:Class path (its
    parameter group is registered on the way). ParameterError lists the known names."""
    eps = registered_controllers()
    try:
        if name in eps:
            cls = eps[name].load()
            group = name
        elif ":" in name:
            module, _, attr = name.partition(":")
            cls = importlib.import_module(module)
            for part in attr.split("."):
                cls = getattr(cls, part)
            group = str(getattr(cls, "name", "") or attr.split(".")[-1].lower())
        else:
            raise unknown_controller(name)
    except (ImportError, AttributeError) as err:
        raise ParameterError("run.controller", name, f"an importable module:Class ({err}); "
                             "registered: " + ", ".join(controller_names())) from None
    if not isinstance(cls, type):
        raise ParameterError("run.controller", name, "a class")
    params_type: type = getattr(cls, "Params", None) or _no_params(name)
    register_controller_group(group, params_type, name if group != name else None)
    return cls


def unknown_controller(name: str) -> ParameterError:
    """The one-line error for a controller name that is not registered (lists the known)."""
    return ParameterError("run.controller", name, "one of " + ", ".join(controller_names())
                          + " (registered controllers) or a module:Class path"
                          + nearest(name, controller_names()))


def _no_params(name: str) -> type:
    raise ParameterError("run.controller", name, "a controller class with a Params dataclass "
                         "(see hexapod_control.core.controller_api)")


def controller_group(name: str) -> str:
    """The parameter group of controller ``name`` (its own name, or a module:Class path's
    declared name)."""
    if name in _CONTROLLER_ALIASES:
        return _CONTROLLER_ALIASES[name]
    if ":" in name:
        load_controller_class(name)
        return _CONTROLLER_ALIASES.get(name, name)
    return name


def _discover() -> None:
    """Register the parameter groups of every entry-point controller (once)."""
    global _discovering, _discovered
    if _discovered or _discovering:
        return
    _discovering = True
    try:
        for name, ep in registered_controllers().items():
            register_controller_group(name, ep.load().Params)
        _discovered = True
    finally:
        _discovering = False


@dataclass(frozen=True)
class HexapodParams:
    """All parameters; ``HexapodParams()`` has no defaults of its own: use :func:`load_params`."""

    robot: RobotParams
    body: BodyParams
    ground: GroundParams
    gait: GaitParams
    actuator: ActuatorParams
    sim: SimParams
    run: RunParams
    #: (group name, parameters) of every controller group, in listing order.
    controllers: tuple[tuple[str, Any], ...] = ()

    def __getattr__(self, name: str) -> Any:
        """A controller's group by name: ``p.pd_p``, ``p.pd_alpha``."""
        if name.startswith("__") or name == "controllers":
            raise AttributeError(name)
        for group, values in self.controllers:
            if group == name:
                return values
        raise AttributeError(f"no parameter group {name!r}")

    # -- derived quantities --------------------------------------------------
    @property
    def cycle_time(self) -> float:
        """T = L_S / V_F (s)."""
        return self.gait.step_length / self.gait.velocity

    @property
    def substeps(self) -> int:
        """Physics steps per control period."""
        return int(round(self.sim.control_period / self.sim.dt))

    def gains(self, controller: str) -> Any:
        """Parameters of ``controller`` (its group: GainParams for 'pd_p', ...); a group
        this set was loaded without takes the spec table's defaults."""
        group = controller_group(check_controller(controller))
        for name, values in self.controllers:
            if name == group:
                return values
        if group not in _CONTROLLER_GROUPS:
            raise unknown_controller(controller)
        return _default_group(group)

    def with_values(self, **dotted: Any) -> "HexapodParams":
        """A validated copy with some parameters changed:
        ``p.with_values(**{'ground.scale': 2})``."""
        flat = self.to_flat()
        for name, value in dotted.items():
            if name not in flat:
                raise unknown_parameter(name, value)
            flat[name] = value
        return from_flat(flat)

    def with_checked(self, groups: Mapping[str, Mapping[str, Any]]) -> "HexapodParams":
        """A copy with values already checked one by one set, {group: {name: value}}, model
        groups and controller groups alike, without the cross-parameter checks of
        :func:`from_flat` (for live changes, which cannot affect them)."""
        model = {g: replace(getattr(self, g), **kv) for g, kv in groups.items()
                 if g not in _CONTROLLER_GROUPS}
        ctl = dict(self.controllers)
        for g, kv in groups.items():
            if g in _CONTROLLER_GROUPS:
                ctl[g] = replace(ctl[g] if g in ctl else self.gains(g), **kv)
        order = [g for g, _ in self.controllers] + [g for g in ctl if g not in
                                                      dict(self.controllers)]
        return replace(self, **model, controllers=tuple((g, ctl[g]) for g in order))

    def to_flat(self) -> dict[str, Any]:
        """Dotted name -> value, the ROS parameter view."""
        out: dict[str, Any] = {}
        own = dict(self.controllers)
        for group in _GROUP_TYPES:
            values = own.get(group) if group in _CONTROLLER_GROUPS else getattr(self, group)
            if values is None:
                continue
            for f in fields(values):
                out[f"{group}.{f.name}"] = getattr(values, f.name)
        return out


def _default_group(group: str) -> Any:
    """A controller group from its spec table's defaults (ParameterError if one lacks a
    default)."""
    t = _CONTROLLER_GROUPS[group]
    values = {}
    for f in fields(t):
        spec: Spec = f.metadata["spec"]
        if spec.default is None:
            raise ParameterError(f"{group}.{f.name}", None, "a value in the params file "
                                 f"({spec.allowed()})")
        values[f.name] = check_spec(f"{group}.{f.name}", spec, spec.default)
    return t(**values)


def specs() -> dict[str, Spec]:
    """Dotted parameter name -> :class:`Spec`, for every parameter."""
    return {f"{g}.{f.name}": f.metadata["spec"] for g, t in _GROUP_TYPES.items()
            for f in fields(t)}


class _Specs(dict[str, Spec]):
    """:func:`specs` as a dict that reads the registered controllers on first use."""

    def refresh(self) -> None:
        """Rebuild from the groups known now."""
        dict.clear(self)
        dict.update(self, specs())

    def _ready(self) -> None:
        if not _discovered and not _discovering:
            _discover()
            self.refresh()

    def __getitem__(self, key: str) -> Spec:
        self._ready()
        return dict.__getitem__(self, key)

    def __contains__(self, key: object) -> bool:
        self._ready()
        return dict.__contains__(self, key)

    def __iter__(self) -> Any:
        self._ready()
        return dict.__iter__(self)

    def __len__(self) -> int:
        self._ready()
        return dict.__len__(self)

    def get(self, key: str, default: Any = None) -> Any:
        self._ready()
        return dict.get(self, key, default)

    def items(self) -> Any:
        self._ready()
        return dict.items(self)

    def keys(self) -> Any:
        self._ready()
        return dict.keys(self)

    def values(self) -> Any:
        self._ready()
        return dict.values(self)


SPECS: _Specs = _Specs()


def check_value(name: str, value: Any) -> Any:
    """Check one parameter against its spec; return it converted (int -> float where due)."""
    spec = SPECS.get(name)
    if spec is None:
        raise unknown_parameter(name, value)
    return check_spec(name, spec, value)


def as_kind(name: str, value: Any, text: bool = False) -> Any:
    """``value`` in the type of parameter ``name`` where it is the same number in the other
    numeric type: an int for a float parameter is that float, an integral float for an int
    parameter that int; with ``text``, a string that reads as a number (:func:`read_number`:
    ``1e6``, ``.inf``) for a numeric parameter is that number. Anything else (a bool, another
    string, an unknown name) is returned as it is, for :func:`check_value` to judge. For the
    ROS side, which stores what it is sent: ``ros2 param set NODE ground.k_y 1000000`` sends
    an integer, ``... 1e6`` the string ``'1e6'`` (it reads its text as YAML 1.1)."""
    spec = SPECS.get(name)
    if spec is None or isinstance(value, bool):
        return value
    if text and isinstance(value, str) and spec.kind in (int, float):
        try:
            value = read_number(value)
        except ValueError:
            return value
    if spec.kind is float and isinstance(value, int):
        return float(value)
    if spec.kind is int and isinstance(value, float) and value.is_integer():
        return int(value)
    return value


#: How a type is named in messages (a value's, or the one a parameter expects).
TYPE_NAMES = {bool: "a boolean", int: "an integer", float: "a float", str: "a string",
              list: "a list", dict: "a mapping", type(None): "no value"}


def wrong_type(name: str, spec: Spec, value: Any) -> ParameterError:
    """The error for a value of the wrong type: the parameter, the value, the allowed values
    and what was expected instead of what came (``parameter 'ground.k_y' = 'soft' is
    invalid: allowed float in [0, 1e+12] (a string, where a float is expected)``)."""
    found = TYPE_NAMES.get(type(value), f"a {type(value).__name__}")
    return ParameterError(name, value, f"{spec.allowed()} ({found}, where "
                                       f"{TYPE_NAMES[spec.kind]} is expected)")


def read_number(text: str) -> float:
    """A number written as text, read like the params file reads it (``1e6``, ``.inf``,
    ``inf``); raises ValueError if it is not one."""
    try:
        value = parse_yaml(text) if text.strip() else None
    except yaml.YAMLError:
        raise ValueError(text) from None
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        if text.strip().lower() in ("inf", "+inf", "-inf", "nan"):
            return float(text)
        raise ValueError(text)
    return float(value)


def check_spec(name: str, spec: Spec, value: Any) -> Any:
    """``value`` checked against ``spec`` (ParameterError naming ``name``), converted."""
    if spec.kind is bool:
        if not isinstance(value, bool):
            raise wrong_type(name, spec, value)
        return value
    if spec.kind is str:
        if not isinstance(value, str):
            raise wrong_type(name, spec, value)
        if spec.choices and value not in spec.choices:
            raise ParameterError(name, value, spec.allowed())
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise wrong_type(name, spec, value)
    if spec.kind is int:
        if isinstance(value, float) and not value.is_integer():
            raise ParameterError(name, value, spec.allowed())
        value = int(value)
    else:
        value = float(value)
    if math.isnan(value) or (math.isinf(value) and not (spec.allow_inf and value > 0)):
        raise ParameterError(name, value, spec.allowed())
    if spec.lo is not None and (value < spec.lo or (spec.lo_open and value == spec.lo)):
        raise ParameterError(name, value, spec.allowed())
    if spec.hi is not None and (value > spec.hi or (spec.hi_open and value == spec.hi)):
        raise ParameterError(name, value, spec.allowed())
    return value


def check_controller(controller: str) -> str:
    """Validate a controller name: a registered controller or a module:Class path (loaded
    when a run needs it). ParameterError lists the registered names."""
    name = str(check_value("run.controller", controller))
    if ":" not in name and name not in controller_names():
        raise unknown_controller(name)
    return name


def validate(p: HexapodParams) -> HexapodParams:
    """Cross-parameter checks (single values are checked on construction by :func:`from_flat`).

    Raises :class:`ParameterError` naming the offending parameter.
    """
    ratio = p.sim.control_period / p.sim.dt
    if abs(ratio - round(ratio)) > 1e-9 * ratio or round(ratio) < 1:
        raise ParameterError("sim.control_period", p.sim.control_period,
                             f"an integer multiple of sim.dt = {p.sim.dt:g}")
    # Reachability of the whole gait: the hip-foot distance over a cycle (eq. 4a).
    from .gait import reach_bounds  # numba: loaded only when a gait is checked

    lo, hi = reach_bounds(p)
    r_min = abs(p.robot.leg_length_1 - p.robot.leg_length_2)
    r_max = p.robot.leg_length_1 + p.robot.leg_length_2
    if hi >= r_max:
        name = _reach_culprit(p, ("gait.body_height", "gait.step_length"), too_far=True)
        raise ParameterError(name, p.to_flat()[name],
                             f"a gait whose hip-foot distance stays below L1+L2 = {r_max:g} m "
                             f"(this one reaches {hi:.4g} m with {_gait_text(p)}: "
                             f"unreachable gait)")
    if lo <= r_min:
        name = _reach_culprit(p, ("gait.body_height", "gait.foot_clearance"), too_far=False)
        raise ParameterError(name, p.to_flat()[name],
                             f"a gait whose hip-foot distance stays above |L1-L2| = {r_min:g} m "
                             f"(this one comes to {lo:.4g} m with {_gait_text(p)}: "
                             f"unreachable gait)")
    return p


def _gait_text(p: HexapodParams) -> str:
    g = p.gait
    return (f"body_height {g.body_height:g} m, step_length {g.step_length:g} m, "
            f"foot_clearance {g.foot_clearance:g} m")


@lru_cache(maxsize=1)
def _base_flat() -> dict[str, Any]:
    return {k: v for k, v in read_params_file(default_params_path()).items() if k in SPECS}


def _reach_culprit(p: HexapodParams, candidates: tuple[str, ...], too_far: bool) -> str:
    """The parameter at fault for an unreachable gait: the first of ``candidates`` that
    differs from the shipped base case and, put back to its base value, makes the gait
    reach (else the first that differs, else the first candidate)."""
    from .gait import reach_bounds

    flat = p.to_flat()
    base = _base_flat()
    changed = [n for n in candidates if flat[n] != base.get(n, flat[n])]
    r_min = abs(p.robot.leg_length_1 - p.robot.leg_length_2)
    r_max = p.robot.leg_length_1 + p.robot.leg_length_2
    for name in changed:
        group, _, key = name.partition(".")
        trial = replace(p, **{group: replace(getattr(p, group), **{key: base[name]})})
        lo, hi = reach_bounds(trial)
        if (hi < r_max) if too_far else (lo > r_min):
            return name
    return changed[0] if changed else candidates[0]


def from_flat(flat: Mapping[str, Any]) -> HexapodParams:
    """Build and validate parameters from dotted names; every parameter must be present."""
    groups: dict[str, dict[str, Any]] = {g: {} for g in _GROUP_TYPES}
    for name, value in flat.items():
        value = check_value(name, value)
        group, _, key = name.partition(".")
        groups[group][key] = value
    for g, t in _GROUP_TYPES.items():
        for f in fields(t):
            if f.name not in groups[g]:
                spec = SPECS[f"{g}.{f.name}"]
                if spec.default is not None:  # a parameter newer than the file
                    groups[g][f.name] = check_spec(f"{g}.{f.name}", spec, spec.default)
                    continue
                raise ParameterError(f"{g}.{f.name}", None, "a value in the params file "
                                     f"({spec.allowed()})")
    model = {g: t(**groups[g]) for g, t in _MODEL_GROUPS.items()}
    ctrl = tuple((g, t(**groups[g])) for g, t in _GROUP_TYPES.items()
                 if g in _CONTROLLER_GROUPS)
    p = HexapodParams(**model, controllers=ctrl)
    check_controller(p.run.controller)
    return validate(p)


#: The shipped params file, relative to a ROS prefix (and to the source tree's src/).
PARAMS_FILE = Path("hexapod_bringup") / "config" / "hexapod.yaml"


def default_params_path() -> Path:
    """The shipped params file with the paper's base experiment: hexapod_bringup's
    ``config/hexapod.yaml``, found as ROS tools find it (``share/hexapod_bringup`` under an
    ``AMENT_PREFIX_PATH`` prefix), else in the source tree beside this package."""
    for prefix in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
        candidate = Path(prefix) / "share" / PARAMS_FILE if prefix else None
        if candidate is not None and candidate.is_file():
            return candidate.resolve()
    return Path(__file__).resolve().parents[3] / PARAMS_FILE


#: Parameters of the nodes themselves (not of the model), by node: a params file may set
#: them in the node's own section or in '/**'. ``use_sim_time`` is every node's.
def _node(kind: type, default: Any, desc: str, lo: float | None = None,
          hi: float | None = None, *, lo_open: bool = False,
          choices: tuple[str, ...] = ()) -> Spec:
    return Spec(kind, desc, lo, hi, lo_open, False, choices, False, default)


_TIMEOUT = _node(float, 60.0, "wall s to wait for the nodes named, then start anyway",
                 0.0, 1e6)
_BATCH = "wall s between two takes of the queued messages"
_RT = _node(int, 0, "SCHED_FIFO priority of the node's control path: its main thread and "
            "Fast DDS receive and event threads (0 = normal scheduling; needs "
            "CAP_SYS_NICE or an rtprio limit, else a warning and normal scheduling)", 0, 98)
_RT_DDS = _node(int, 0, "SCHED_FIFO priority of the node's Fast DDS receive and event "
                "threads (0 = normal scheduling; needs CAP_SYS_NICE or an rtprio limit, else "
                "a warning and normal scheduling)", 0, 98)
#: Each node's own parameters (read at start, read-only on the node): type, default, range,
#: meaning. Checked when a params file is read and when the node declares them.
NODE_PARAMS: dict[str, dict[str, Spec]] = {
    "hexapod_sim": {
        "stop_at_end": _node(bool, False, "stop (and exit) after the tick at run.duration"),
        "wait_for": _node(str, "trajectory_generator,pd_p_controller,pd_pf_controller,metrics",
                          "comma-separated nodes whose endpoints must be matched before "
                          "tick 0 ('' = none)"),
        "startup_timeout": _TIMEOUT,
        "switch_at": _node(float, -1.0, "simulated s of a scripted switch (-1 = none)",
                           -1.0, 1e9),
        "switch_to": _node(str, "", "controller of the scripted switch ('' = none)",
                           choices=("",) + CONTROLLERS),
        "summary_path": _node(str, "", "write the end summary as JSON to this file ('' = no)"),
        "rt_priority": _RT,
        "ground_seed": _node(int, -1, "uneven ground: the seed of every foot's factors per "
                             "touchdown, as `hexapod montecarlo --first-seed` (-1 = uniform "
                             "ground)", -1, 2**53 - 1),
        "ground_spread": _node(float, 0.0, "uneven ground: sigma of ln(factor) (0.2 = "
                               "`hexapod montecarlo --spread 20`)", 0.0, 2.0),
    },
    "trajectory_generator": {
        "lookahead": _node(int, 50, "ticks published ahead of the newest state", 0, 1000),
        "publish_interval": _node(float, 0.005, "wall s between two bursts of references "
                                  "(0: a burst at every state)", 0.0, 1.0),
        "rt_priority": _RT},
    "pd_p_controller": {"autostart": _node(bool, True, "configure and activate at start"),
                        "rt_priority": _RT},
    "pd_pf_controller": {"autostart": _node(bool, True, "configure and activate at start"),
                         "rt_priority": _RT},
    "metrics": {
        "bag_path": _node(str, "", "bag directory, must not exist ('' = bags/<date-time>)"),
        "batch_interval": _node(float, 0.005, _BATCH, 0.0, 1.0),
        "reorder_window": _node(float, 0.5, "sim s a chunk waits for late messages behind "
                                "the ticks", 0.0, 60.0),
        "max_bag_size": _node(int, 0, "bytes per MCAP file before a new one starts "
                              "(0: one file)", 0, 2**62),
        "max_bag_duration": _node(float, 0.0, "sim s per MCAP file before a new one starts "
                                  "(0: one file)", 0.0, 1e9),
        "rt_priority": _RT_DDS,
    },
    "markers": {
        "rate": _node(float, 30.0, "markers per simulated second (Hz)", 0.0, 1e6,
                      lo_open=True),
        "deliver_to": _node(str, "metrics", "comma-separated nodes that must receive the "
                            "markers from t = 0 ('' = none)"),
        "startup_timeout": _TIMEOUT,
        "rt_priority": _RT_DDS,
    },
    "foxglove_bridge": {
        "host": _node(str, "127.0.0.1", "address to listen on"),
        "port": _node(int, 8765, "WebSocket port (0 = any free one)", 0, 65535),
        "batch_interval": _node(float, 0.01, _BATCH, 0.0, 1.0),
        "rt_priority": _RT_DDS,
    },
}
COMMON_NODE_PARAMS = ("use_sim_time",)
#: What rcl and rclpy declare on every node, found in a `ros2 param dump`: accepted in a
#: params file and left to rcl (not passed on: each node declares its own).
ROS_OWN_PARAMS = ("start_type_description_service",)
#: rclpy's QoS overrides group (``qos_overrides./topic.publisher.depth``): left to rclpy.
QOS_OVERRIDES = "qos_overrides"


class YamlLoader(yaml.SafeLoader):  # type: ignore[misc]  # PyYAML ships no types
    """PyYAML's safe loader with YAML 1.2 floats, as rcl's parser reads them: ``1e6``,
    ``1E-3``, ``.inf``, ``-.inf``, ``.nan`` are floats (PyYAML's YAML 1.1 reads ``1e6``
    as a string)."""


YamlLoader.yaml_implicit_resolvers = {
    k: [r for r in v if r[0] != "tag:yaml.org,2002:float"]
    for k, v in yaml.SafeLoader.yaml_implicit_resolvers.items()}
YamlLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
                 |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
                 |\.[0-9_]+(?:[eE][-+]?[0-9]+)?
                 |[-+]?\.(?:inf|Inf|INF)
                 |\.(?:nan|NaN|NAN))$""", re.X),
    list("-+0123456789."))


def parse_yaml(text: str) -> Any:
    """Parse YAML text the one way the project does (params files, ``--set`` values)."""
    return yaml.load(text, Loader=YamlLoader)  # noqa: S506 (a SafeLoader subclass)


def nearest(name: str, known: Any) -> str:
    """`` (did you mean 'x'?)`` for the closest known name, or '' if none is close."""
    close = difflib.get_close_matches(name, list(known), n=1, cutoff=0.6)
    return f" (did you mean '{close[0]}'?)" if close else ""


def unknown_parameter(name: str, value: Any) -> ParameterError:
    """The error for a parameter name that is not in :data:`SPECS` (nearest known name)."""
    return ParameterError(name, value, "a known parameter name" + nearest(name, SPECS))


def _group_names() -> list[str]:
    return list(_GROUP_TYPES)


def _node_param_names() -> set[str]:
    return {n for names in NODE_PARAMS.values() for n in names} | set(COMMON_NODE_PARAMS)


def _flatten(path: Path, section: str, tree: Mapping[str, Any], out: dict[str, Any]) -> None:
    """Model parameters (``group: {key: value}``) and node parameters of one section."""
    own = _node_param_names()
    for key, value in tree.items():
        key = str(key)
        if key in ROS_OWN_PARAMS or key == QOS_OVERRIDES:
            continue
        if key in _GROUP_TYPES:
            if not isinstance(value, Mapping):
                raise ParamsFileError(
                    f"params file {path}: '{key}' must be a group of parameters "
                    f"({key}.{fields(_GROUP_TYPES[key])[0].name}: ...), got {value!r}")
            for sub, v in value.items():
                name = f"{key}.{sub}"
                if name not in SPECS:
                    raise ParamsFileError(f"params file {path}: "
                                          f"{unknown_parameter(name, v)}")
                if isinstance(v, Mapping):
                    raise ParamsFileError(f"params file {path}: parameter '{name}' must be a "
                                          f"value ({SPECS[name].allowed()}), got a group")
                out[name] = v
        elif key in own:
            if isinstance(value, Mapping):
                raise ParamsFileError(f"params file {path}: node parameter '{key}' must be a "
                                      f"value, got a group")
            _check_node_value(path, section, key, value)
            out[key] = value
        elif isinstance(value, Mapping):
            raise ParamsFileError(f"params file {path}: unknown group '{key}'"
                                  + nearest(key, _group_names()))
        else:
            dotted = [n for n in SPECS if n.endswith("." + key)]
            hint = (f" (did you mean '{dotted[0]}'?)" if dotted
                    else nearest(key, sorted(own) + _group_names()))
            raise ParamsFileError(f"params file {path}: unknown parameter '{key}' in section "
                                  f"'{section}'{hint}")


def _node_table(node: str) -> dict[str, Spec]:
    """The node parameters of node ``node`` (a plug-in's node: a controller node's)."""
    return NODE_PARAMS.get(node) or NODE_PARAMS["pd_p_controller"]


def _check_node_value(path: Path, section: str, key: str, value: Any) -> None:
    """A node parameter in a params file: known to the section's node (to some node under
    ``/**``) and valid for every node that has it."""
    node = section.lstrip("/")
    owners = ([node] if section != "/**" else
              [n for n, table in NODE_PARAMS.items() if key in table])
    if key in COMMON_NODE_PARAMS:
        return
    if section != "/**" and key not in _node_table(node):
        raise ParamsFileError(f"params file {path}: '{key}' is not a parameter of node "
                              f"'{node}'" + nearest(key, _node_table(node)))
    for owner in owners:
        try:
            check_spec(key, _node_table(owner)[key], value)
        except ParameterError as err:
            raise ParamsFileError(f"params file {path}: node '{owner}': {err}") from None


def read_params_file(path: str | Path) -> dict[str, Any]:
    """Dotted name -> value from a ROS 2 params file (the ``/**`` section, then node sections).

    Strict: an empty file, a file that is not ``<node>: ros__parameters: {...}``, an unknown
    section, group or parameter (named, with the nearest known name) or a group given a
    value raises :class:`ParamsFileError`. Node parameters (:data:`NODE_PARAMS`) come back
    under their plain names. Numbers are read as rcl reads them (:class:`YamlLoader`).
    """
    path = Path(path)
    try:
        doc = parse_yaml(path.read_text())
    except OSError as err:
        raise ParamsFileError(f"cannot read params file {path}: {err.strerror}") from err
    except (yaml.YAMLError, UnicodeDecodeError) as err:
        first = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        raise ParamsFileError(f"params file {path} is not valid YAML: {first}") from err
    layout = "expected '/**: ros__parameters: <group>: <name>: value'"
    if doc is None or doc == {}:
        raise ParamsFileError(f"params file {path} is empty: {layout}")
    if not isinstance(doc, Mapping):
        raise ParamsFileError(f"params file {path} holds {type(doc).__name__} {doc!r}: {layout}")
    # a registered plug-in's node is named as the controller (a `ros2 param dump` of it)
    nodes = ["/**"] + list(NODE_PARAMS) + [c for c in controller_names() if c not in CONTROLLERS]
    flat: dict[str, Any] = {}
    for node, body in doc.items():
        name = str(node).lstrip("/") if str(node) != "/**" else "/**"
        if name not in nodes:
            raise ParamsFileError(f"params file {path}: unknown section '{node}'"
                                  + nearest(str(node), nodes) + f": {layout}")
        if not isinstance(body, Mapping) or not isinstance(body.get("ros__parameters"), Mapping):
            raise ParamsFileError(f"params file {path}: section '{node}' lacks 'ros__parameters'")
        extra = [k for k in body if k != "ros__parameters"]
        if extra:
            raise ParamsFileError(f"params file {path}: section '{node}' has '{extra[0]}' "
                                  f"beside 'ros__parameters'")
        _flatten(path, str(node), body["ros__parameters"], flat)
    return flat


def _dump_only(path: Path) -> bool:
    """Whether the params file at ``path`` has node sections only (no ``/**``)."""
    doc = parse_yaml(path.read_text())
    return isinstance(doc, Mapping) and "/**" not in doc


def load_params(path: str | Path | None = None, **overrides: Any) -> HexapodParams:
    """Load and validate the params file (default: the shipped base experiment).

    A file of node sections only (``/hexapod_sim: ros__parameters: ...``: a `ros2 param
    dump` of one or more nodes) holds what those nodes declare (the sim no controller
    gains): the shipped base experiment's values fill in the rest. A ``/**`` section must be
    complete (a missing parameter is named).
    ``overrides`` use dotted names with '.' replaced by '__' (``ground__scale=2.0``) or can be
    given as a dict via ``load_params(path, **{"ground.scale": 2.0})``.
    """
    flat = read_params_file(path or default_params_path())
    known = {k: v for k, v in flat.items() if k in SPECS}  # the rest: node parameters
    if path is not None and set(SPECS) - set(known) and _dump_only(Path(path)):
        known = {**_base_flat(), **known}
    for name, value in overrides.items():
        name = name.replace("__", ".")
        if name not in SPECS:
            raise unknown_parameter(name, value)
        known[name] = value
    return from_flat(known)


__all__ = [
    "ActuatorParams", "BodyParams", "COMMON_NODE_PARAMS", "CONTROLLERS", "CONTROLLER_GROUP",
    "GainParams", "controller_group", "controller_names", "load_controller_class",
    "register_controller_group", "registered_controllers", "unknown_controller",
    "unregister_controller_group",
    "GaitParams", "GroundParams", "HexapodParams", "INTEGRATORS", "MODES", "NODE_PARAMS",
    "N_LEGS", "QOS_OVERRIDES", "ROS_OWN_PARAMS", "RobotParams", "RunParams", "SPECS",
    "SimParams", "Spec", "YamlLoader",
    "as_kind", "check_controller", "check_spec", "check_value", "default_params_path", "from_flat",
    "load_params", "nearest", "parse_yaml", "read_number", "read_params_file", "unknown_parameter",
    "validate", "wrong_type",
]
