"""Exceptions of the ROS-free core; each message says what was expected and what was found."""
from __future__ import annotations


class HexapodError(Exception):
    """Base class of every error the project raises on purpose."""


class ParameterError(HexapodError, ValueError):
    """A parameter has the wrong type, lies outside its range or makes the gait unreachable.

    ``name`` is the dotted parameter name (as in the YAML file and on the ROS node).
    """

    def __init__(self, name: str, value: object, allowed: str) -> None:
        self.name = name
        self.value = value
        self.allowed = allowed
        super().__init__(f"parameter '{name}' = {value!r} is invalid: allowed {allowed}")


class ParamsFileError(HexapodError):
    """The parameter file cannot be read or does not have the ROS 2 params-file layout."""


class UnreachableTargetError(HexapodError, ValueError):
    """An inverse-kinematics target lies outside the leg's workspace annulus."""


class DivergenceError(HexapodError, ArithmeticError):
    """The numerical integration blew up (non-finite or absurd state)."""


class CdrError(HexapodError, ValueError):
    """Bytes are not the serialized (little-endian CDR) message they should be."""
