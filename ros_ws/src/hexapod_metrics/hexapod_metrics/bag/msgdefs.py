"""ROS 2 Jazzy message definitions as rosbag2 stores them (``ros2msg`` full text) and their
type hashes, read from the installed ``share/<pkg>/msg/<Type>.msg`` and ``.json`` files.

The full text is what rosbag2's ``LocalMessageDefinitionSource`` writes: the root ``.msg``
verbatim (comments kept), then every dependency once, depth first (each type's own
dependencies sorted by name), each after an 80-character ``=`` line and a ``MSG: pkg/Type``
line. Hashes are the RIHS01 hashes of the ``.json`` type descriptions. The files are looked
up under this interpreter's prefix (where the ROS wheels install them) and every
``AMENT_PREFIX_PATH`` entry; no rclpy is imported.
"""

from __future__ import annotations

import json
import os
import re
import sys
from functools import lru_cache
from pathlib import Path
from typing import NamedTuple

__all__ = [
    'MESSAGE_TYPES',
    'TYPE_CLOCK',
    'TYPE_DIAGNOSTIC_ARRAY',
    'TYPE_JOINT_STATE',
    'TYPE_MARKER_ARRAY',
    'TYPE_STRING',
    'MessageDefinitionError',
    'MessageType',
    'load',
    'lookup',
]


class MessageType(NamedTuple):
    """A ROS 2 message type as stored in a bag."""

    name: str
    """Full type name, e.g. ``sensor_msgs/msg/JointState``."""
    definition: str
    """rosbag2 ``ros2msg`` full text including dependencies."""
    type_hash: str
    """RIHS01 type description hash."""


class MessageDefinitionError(LookupError):
    """A message type's ``.msg`` file is not installed where we look."""


TYPE_JOINT_STATE = 'sensor_msgs/msg/JointState'
TYPE_STRING = 'std_msgs/msg/String'
TYPE_CLOCK = 'rosgraph_msgs/msg/Clock'
TYPE_DIAGNOSTIC_ARRAY = 'diagnostic_msgs/msg/DiagnosticArray'
TYPE_MARKER_ARRAY = 'visualization_msgs/msg/MarkerArray'

_PRIMITIVES = {
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16',
    'int32', 'uint32', 'int64', 'uint64', 'string', 'wstring',
}
_SEPARATOR = '=' * 80


def _share_dirs() -> list[Path]:
    prefixes = [sys.prefix, *os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep)]
    return [Path(p) / 'share' for p in dict.fromkeys(prefixes) if p]


def _file(pkg: str, name: str, suffix: str) -> Path:
    for share in _share_dirs():
        path = share / pkg / 'msg' / f'{name}{suffix}'
        if path.is_file():
            return path
    where = ', '.join(str(s) for s in _share_dirs())
    msg = (f'message definition {pkg}/msg/{name}{suffix} not found under {where}: install '
           'the ROS 2 message wheels (scripts/setup.sh) or set AMENT_PREFIX_PATH')
    raise MessageDefinitionError(msg)


def _field_types(text: str, pkg: str) -> list[str]:
    """``pkg/Type`` of every non-primitive field of a ``.msg`` text (constants skipped)."""
    out = []
    for line in text.splitlines():
        words = line.split('#', 1)[0].split()
        if len(words) < 2 or '=' in words[1] or (len(words) > 2 and words[2].startswith('=')):
            continue
        base = re.sub(r'<=\d+$', '', re.sub(r'\[.*\]$', '', words[0]))
        if base in _PRIMITIVES:
            continue
        if '/' in base:
            dep_pkg, dep = base.split('/')[0], base.rsplit('/', 1)[1]
        elif base == 'Header':
            dep_pkg, dep = 'std_msgs', 'Header'
        else:
            dep_pkg, dep = pkg, base
        out.append(f'{dep_pkg}/{dep}')
    return out


@lru_cache(maxsize=64)
def _msg_text(full: str) -> str:
    pkg, _, name = full.partition('/')
    return _file(pkg, name, '.msg').read_text(encoding='utf-8')


@lru_cache(maxsize=64)
def load(msgtype: str) -> MessageType:
    """The definition and hash of ``pkg/msg/Type`` from the installed files."""
    pkg, _, name = msgtype.replace('/msg/', '/').partition('/')
    root = f'{pkg}/{name}'
    seen: list[str] = []

    def visit(full: str) -> None:
        for dep in sorted(set(_field_types(_msg_text(full), full.split('/')[0]))):
            if dep not in seen and dep != root:
                seen.append(dep)
                visit(dep)

    visit(root)
    parts = [_msg_text(root)]
    parts += [f'{_SEPARATOR}\nMSG: {dep}\n{_msg_text(dep)}' for dep in seen]
    description = json.loads(_file(pkg, name, '.json').read_text(encoding='utf-8'))
    full_name = f'{pkg}/msg/{name}'
    hashes = {h['type_name']: h['hash_string'] for h in description['type_hashes']}
    return MessageType(full_name, '\n'.join(parts), hashes[full_name])


def lookup(msgtype: str) -> MessageType | None:
    """The type ``pkg/msg/Type`` or ``pkg/Type`` (installed files); None if unknown."""
    parts = msgtype.split('/')
    if len(parts) == 2:
        msgtype = f'{parts[0]}/msg/{parts[1]}'
    if len(msgtype.split('/')) != 3:
        return None
    try:
        return load(msgtype)
    except MessageDefinitionError:
        return None


MESSAGE_TYPES: dict[str, MessageType] = {
    t: load(t) for t in (TYPE_JOINT_STATE, TYPE_STRING, TYPE_CLOCK, TYPE_DIAGNOSTIC_ARRAY,
                         TYPE_MARKER_ARRAY)
}
"""The types this project records."""
