"""Bags in one import: write with :class:`BagWriter`, read with :func:`open_bag`.

A bag is a rosbag2 (Jazzy) directory: ``metadata.yaml`` and one MCAP file, readable by
``rosbags`` and any MCAP reader, and still readable up to its last flushed chunk after the
writer was killed (``Bag.truncated`` then says so).
"""

from __future__ import annotations

from .bag_reader import (
    Bag,
    TopicInfo,
    iter_joint_state_blocks,
    open_bag,
    read_joint_state_arrays,
    read_joint_state_topics,
)
from .bag_writer import QOS_PRESETS, RESERVE_NAME, BagWriter, QosProfile, qos_yaml
from .cdr import DiagnosticStatus, JointStateArrays
from .errors import BagError, BagReadError, BagStorageError, BagTruncatedWarning, BagWriteError

__all__ = [
    'QOS_PRESETS',
    'RESERVE_NAME',
    'Bag',
    'BagError',
    'BagReadError',
    'BagStorageError',
    'BagTruncatedWarning',
    'BagWriteError',
    'BagWriter',
    'DiagnosticStatus',
    'JointStateArrays',
    'QosProfile',
    'TopicInfo',
    'iter_joint_state_blocks',
    'open_bag',
    'qos_yaml',
    'read_joint_state_arrays',
    'read_joint_state_topics',
]
