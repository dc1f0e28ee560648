"""The parameters a bag records: checksummed records in the MCAP, mirrored in metadata.yaml.

The MCAP's Metadata records named ``hexapod_parameters`` (hexapod_common/core/param_log.py) are
the truth: each node's start values and every runtime change with the tick it took
effect. They are read from a bare ``.mcap`` as well as from a bag directory, and also from a
file whose writer was killed (the records are written at once, outside the chunks).
A record that fails its checksum, or a ``metadata.yaml`` whose mirror disagrees with the
MCAP, makes the bag refused (:class:`~.errors.BagReadError`): numbers computed with
parameters that cannot be trusted would be misread. Bags without records (older ones)
fall back to ``metadata.yaml``'s ``custom_data``, then to the shipped defaults, and say so.
"""
from __future__ import annotations

import functools
import json
from typing import Any, NamedTuple

from hexapod_common.core.errors import HexapodError
from hexapod_common.core.param_log import RECORD_NAME, ParamRecord, ParamRecordError, ParamTimeline
from hexapod_common.core.param_log import timeline as make_timeline
from hexapod_common.core.controller_names import check_name
from hexapod_common.core.params import (CONTROLLERS, SPECS, HexapodParams, controller_names,
                                        from_flat, load_params)

from ..bag import Bag
from ..bag import BagReadError
from .recording import PARAMS_KEY, RECORDS_KEY, params_from_custom_data

FROM_MCAP = "recorded in the bag (MCAP records, checksummed)"
FROM_YAML = "metadata.yaml only (no checksummed record in the MCAP)"
DEFAULTS = "the shipped defaults (the bag records none)"


class BagParams(NamedTuple):
    """The start parameters, where they came from (with the recorded start values of
    controllers not registered here, e.g. a plug-in that is not installed on this machine:
    taken as recorded, unchecked, and named in ``source``: :data:`FOREIGN`), and the
    timeline of changes (if any)."""

    params: HexapodParams
    source: str
    timeline: ParamTimeline | None
    records: tuple[ParamRecord, ...] = ()


#: How ``source`` names the parameters of controllers not registered here.
FOREIGN = "parameters of controllers not registered here, taken as recorded (unchecked)"


def _foreign(name: str) -> bool:
    """Whether ``name`` is a parameter of a group no controller registered here has."""
    group, dot, _ = name.partition(".")
    return bool(dot) and not any(n.startswith(group + ".") for n in SPECS)


def read_records(bag: Bag) -> list[ParamRecord]:
    """Every parameter record of the MCAP, checked; BagReadError names a damaged one."""
    raw = bag.metadata_records(RECORD_NAME)
    out = []
    for i, (_, items) in enumerate(raw):
        try:
            out.append(ParamRecord.from_map(items, f"parameter record {i + 1} of {len(raw)}"))
        except ParamRecordError as err:
            msg = f"{bag.path}: {err}; refusing to analyse a bag whose parameters are damaged"
            raise BagReadError(msg) from err
    return out


def _check_mirror(bag: Bag, custom: dict[str, Any], records: list[ParamRecord]) -> None:
    """metadata.yaml's mirror must be a prefix of the MCAP's records (it may lag them)."""
    where = f"{bag.path}: metadata.yaml"
    if RECORDS_KEY in custom:
        try:
            mirror = json.loads(custom[RECORDS_KEY])
        except (TypeError, ValueError) as err:
            raise BagReadError(f"{where}: {RECORDS_KEY} is not JSON ({err})") from err
        mcap = [r.to_map() for r in records]
        if not isinstance(mirror, list) or mirror != mcap[:len(mirror)]:
            raise BagReadError(f"{where}'s parameter records disagree with the MCAP's "
                               f"checksummed ones: refusing to guess which is right")
    if PARAMS_KEY in custom:
        try:
            flat = json.loads(custom[PARAMS_KEY])
        except (TypeError, ValueError) as err:
            raise BagReadError(f"{where}: {PARAMS_KEY} is not JSON ({err})") from err
        # the parameters known here, and those of a controller not registered here as the
        # recording machine knew them (its mirror has them: they must be in a start record)
        starts = [{k: v for k, v in r.values.items()
                   if k in SPECS or (k in flat and _foreign(k))}
                  for r in records if r.kind == "start"]
        if flat not in starts:
            bad = sorted(k for k in flat if all(s.get(k) != flat[k] for s in starts))
            raise BagReadError(f"{where}: {PARAMS_KEY} disagrees with the MCAP's checksummed "
                               f"start parameters ({', '.join(bad[:3]) or 'keys'}): refusing "
                               f"to guess which is right")


@functools.lru_cache(maxsize=16)
def _validated(flat_json: str) -> HexapodParams:
    """from_flat of a JSON-encoded flat dict, remembered: its reachability check of the gait
    costs ~50 ms, and analysing a batch of bags of one run's parameters (a sweep's, a
    fuzz's) would pay it per bag. HexapodParams is frozen: sharing one is safe; a failure
    is not remembered (raised again each time).

    ``run.controller`` may name any controller of the graph that recorded the bag (the
    naming rule, core/controller_names.py): a node that joined and was in charge from tick
    0 is no controller registered here; it is kept as recorded."""
    flat = json.loads(flat_json)
    kept: dict[str, Any] = {}
    controller = flat.get("run.controller")
    if isinstance(controller, str) and ":" not in controller \
            and controller not in controller_names():
        kept["controller"] = check_name(controller)
        flat["run.controller"] = CONTROLLERS[0]
    p = from_flat(flat)
    return p.with_checked({"run": kept}) if kept else p


def bag_params(bag: Bag) -> BagParams:
    """The parameters of ``bag`` (see the module docstring)."""
    custom = (bag.metadata or {}).get("custom_data") or {}
    records = read_records(bag)
    if records:
        tl = make_timeline(records, SPECS)
        if tl is None:
            raise BagReadError(f"{bag.path}: parameter records without any start record")
        if missing := sorted(set(SPECS) - set(tl.start)):
            raise BagReadError(f"{bag.path}: the start records lack {', '.join(missing[:3])}")
        _check_mirror(bag, custom, records)
        try:
            p = _validated(json.dumps(tl.start, sort_keys=True))
        except HexapodError as err:
            raise BagReadError(f"{bag.path}: recorded start parameters: {err}") from err
        foreign: dict[str, Any] = {}
        for r in records:
            if r.kind == "start":
                for k, v in r.values.items():
                    if _foreign(k):
                        foreign.setdefault(k, v)
        source = FROM_MCAP + (f"; {FOREIGN}: " + ", ".join(
            f"{k}={v!r}" for k, v in sorted(foreign.items())) if foreign else "")
        return BagParams(p, source, tl, tuple(records))
    try:
        mirrored = params_from_custom_data(custom)
    except (HexapodError, ValueError, TypeError) as err:
        raise BagReadError(f"{bag.path}: metadata.yaml's parameters: {err}") from err
    if mirrored is not None:
        return BagParams(mirrored, FROM_YAML, None)
    return BagParams(load_params(), DEFAULTS, None)


__all__ = ["BagParams", "DEFAULTS", "FOREIGN", "FROM_MCAP", "FROM_YAML", "bag_params",
           "read_records"]
