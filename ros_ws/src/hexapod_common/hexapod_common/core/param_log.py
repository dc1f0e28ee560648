"""Parameter records: what a node's parameters were at start and every change, with its tick.

ROS-free. One :class:`ParamRecord` is one event: ``kind`` ``'start'`` (every parameter the
node owns, at tick 0) or ``'change'`` (the changed parameters only, at the first tick that
runs with them). Its canonical JSON ``payload`` carries a SHA-256 ``sha256``; the pair is
what travels on ``/hexapod/parameters`` (one ``DiagnosticStatus`` per record) and what the
recorder stores in the MCAP as a Metadata record named :data:`RECORD_NAME`, so a bag holds
its parameters itself and a damaged record is detected instead of silently used.
"""
from __future__ import annotations

import hashlib
import json
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from .errors import HexapodError

#: Name of the MCAP Metadata records (and prefix of the DiagnosticStatus names).
RECORD_NAME = "hexapod_parameters"
#: ``controller``: the parameters a controller node that joined the graph declared, read by
#: the sim when it took over (tick = the switch tick; node = the controller's node).
KINDS = ("start", "change", "controller")


class ParamRecordError(HexapodError, ValueError):
    """A parameter record is malformed or fails its checksum."""


def _plain(value: Any) -> Any:
    """A JSON-able copy of a parameter value (ROS arrays become lists)."""
    if isinstance(value, (bool, int, str)) or value is None:
        return value
    if isinstance(value, float):
        return value
    if isinstance(value, (bytes, bytearray)):
        return list(value)
    if isinstance(value, Iterable):
        return [_plain(v) for v in value]
    return str(value)


@dataclass(frozen=True)
class ParamRecord:
    """One start snapshot or runtime change of ``node``'s parameters.

    ``tick`` is the control tick the values took effect at, ``stamp_ns`` its simulated time
    (ns); ``values`` maps dotted parameter names to values.
    """

    node: str
    kind: str
    tick: int
    stamp_ns: int
    values: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ParamRecordError(f"parameter record kind {self.kind!r}: expected one of "
                                   f"{', '.join(KINDS)}")

    @property
    def payload(self) -> str:
        """Canonical JSON of the record (sorted keys, no spaces; inf/nan as JSON allows)."""
        return json.dumps({"node": self.node, "kind": self.kind, "tick": int(self.tick),
                           "stamp_ns": int(self.stamp_ns),
                           "values": {k: _plain(v) for k, v in self.values.items()}},
                          sort_keys=True, separators=(",", ":"))

    @property
    def sha256(self) -> str:
        """Hex SHA-256 of :attr:`payload`."""
        return hashlib.sha256(self.payload.encode()).hexdigest()

    def to_map(self) -> dict[str, str]:
        """The string map stored in the MCAP Metadata record and sent on the topic."""
        return {"payload": self.payload, "sha256": self.sha256}

    @classmethod
    def from_map(cls, m: Mapping[str, str], what: str = "parameter record") -> ParamRecord:
        """Inverse of :meth:`to_map`; raise ParamRecordError if it fails its checksum."""
        payload, digest = m.get("payload"), m.get("sha256")
        if not isinstance(payload, str) or not isinstance(digest, str):
            raise ParamRecordError(f"{what}: no payload/sha256 pair (keys: "
                                   f"{', '.join(sorted(m)) or 'none'})")
        found = hashlib.sha256(payload.encode()).hexdigest()
        if found != digest:
            raise ParamRecordError(f"{what} fails its checksum (sha256 {found[:12]}... != "
                                   f"recorded {digest[:12]}...): the parameters are damaged")
        try:
            d = json.loads(payload)
            rec = cls(str(d["node"]), str(d["kind"]), int(d["tick"]), int(d["stamp_ns"]),
                      dict(d["values"]))
        except (ValueError, KeyError, TypeError) as err:
            raise ParamRecordError(f"{what}: malformed payload ({err})") from err
        if rec.sha256 != digest:  # not canonical: written by something else
            raise ParamRecordError(f"{what}: payload is not in canonical form")
        return rec


#: Parameter groups whose runtime value lives in another node than the sim.
OWNERS = {"pd_p.": "pd_p_controller", "pd_pf.": "pd_pf_controller"}


def owner(name: str, nodes: set[str]) -> str | None:
    """The node whose value of ``name`` acts on the robot, among the recorded ``nodes``.

    Gains act in their controller, everything else in the sim; a bag written by one
    process (``hexapod simulate``) has one node that owns everything.
    """
    if len(nodes) == 1:
        return next(iter(nodes))
    for prefix, node in OWNERS.items():
        if name.startswith(prefix):
            return node
    return "hexapod_sim"


@dataclass(frozen=True)
class ParamTimeline:
    """The model parameters in force over a run: start values and changes at their ticks."""

    start: dict[str, Any]
    changes: tuple[tuple[int, str, str, Any], ...]
    """(tick, node, name, value) of every change that acts on the robot, by tick."""

    def at(self, tick: int) -> dict[str, Any]:
        """Flat values in force at ``tick``."""
        flat = dict(self.start)
        for k, _, name, value in self.changes:
            if k <= tick:
                flat[name] = value
        return flat

    @property
    def change_ticks(self) -> list[int]:
        """Ticks where something changed, ascending, without repeats."""
        return sorted({k for k, *_ in self.changes})


def timeline(records: Iterable[ParamRecord], names: Iterable[str]) -> ParamTimeline | None:
    """The timeline of the parameters ``names`` from a bag's records (None if no start).

    Start values come from the owner of each parameter (its ``start`` record), falling back
    to any node's; changes count only from the parameter's owner.
    """
    recs = list(records)
    names = set(names)
    nodes = {r.node for r in recs}
    starts = {r.node: r for r in recs if r.kind == "start"}
    if not starts:
        return None
    start: dict[str, Any] = {}
    for name in names:
        own = owner(name, nodes)
        src = starts.get(own) if own else None
        for rec in ([src] if src else []) + list(starts.values()):
            if name in rec.values:
                start[name] = rec.values[name]
                break
    changes = sorted(
        ((r.tick, r.node, n, v) for r in recs if r.kind == "change"
         for n, v in r.values.items() if n in names and owner(n, nodes) == r.node),
        key=lambda c: c[0])
    return ParamTimeline(start, tuple(changes))


__all__ = ["KINDS", "OWNERS", "RECORD_NAME", "ParamRecord", "ParamRecordError", "ParamTimeline",
           "owner", "timeline"]
