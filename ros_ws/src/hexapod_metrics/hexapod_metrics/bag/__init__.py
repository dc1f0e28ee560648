"""Bags of this project: rosbag2 (Jazzy) directories of ``metadata.yaml`` and MCAP files.

The only code that touches MCAP bytes. Write with :class:`BagWriter` (crash-safe: every
chunk is followed by a complete, indexed tail), read with :func:`open_bag` (complete bags
from their summary, cut-short ones scanned up to the last complete record, JointStates
decoded vectorised chunk by chunk). Message definitions come from the installed ``.msg``
files (:mod:`.msgdefs`); CDR is ``hexapod_common.core.cdr``. Everything here is ROS-free.
"""

from __future__ import annotations

from .errors import BagError, BagReadError, BagStorageError, BagWriteError
from .msgdefs import MESSAGE_TYPES, MessageDefinitionError, MessageType, lookup
from .reader import (
    Bag,
    TopicInfo,
    iter_joint_state_blocks,
    open_bag,
    read_joint_state_arrays,
    read_joint_state_topics,
)
from .reindex import REINDEXED, ReindexResult, reindex
from .writer import QOS_PRESETS, RESERVE_NAME, BagWriter, QosProfile, qos_yaml

__all__ = [
    'MESSAGE_TYPES',
    'QOS_PRESETS',
    'REINDEXED',
    'RESERVE_NAME',
    'Bag',
    'BagError',
    'BagReadError',
    'BagStorageError',
    'BagWriteError',
    'BagWriter',
    'MessageDefinitionError',
    'MessageType',
    'QosProfile',
    'ReindexResult',
    'TopicInfo',
    'iter_joint_state_blocks',
    'lookup',
    'open_bag',
    'qos_yaml',
    'read_joint_state_arrays',
    'read_joint_state_topics',
    'reindex',
]
