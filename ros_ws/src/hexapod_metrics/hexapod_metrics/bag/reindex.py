"""Rewrite a cut-short bag as a complete one (what ``ros2 bag reindex`` is for rosbag2).

A recorder killed inside the write of a chunk leaves an MCAP whose tail is unfinished: this
project's reader scans it up to its last complete record, the ``mcap`` library's seeking
reader, rosbags and Foxglove's indexed load refuse it. :func:`reindex` copies what is
readable (topics with their types, QoS and type hashes, every message with its log time,
every metadata record, ``metadata.yaml``'s ``custom_data``) into a new bag directory with a
full summary. The copy says where it came from: a ``hexapod_reindexed`` metadata record
(source and the reason it was cut short), which this project's reader reports as truncated,
so an analysis never mistakes it for a complete run.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import NamedTuple

from .errors import BagWriteError
from .reader import REINDEXED, open_bag
from .writer import BagWriter

_RESERVED = ('rosbag2', 'hexapod_writer')


class ReindexResult(NamedTuple):
    """What :func:`reindex` copied."""

    path: Path
    messages: int
    topics: int
    reason: str


def _qos(offered: str) -> str:
    """The writer's QoS preset for a recorded ``offered_qos_profiles`` text."""
    return 'transient_local' if 'transient_local' in offered else 'reliable'


def reindex(src: str | os.PathLike[str], dst: str | os.PathLike[str]) -> ReindexResult:
    """Copy the readable part of bag ``src`` into a new, complete bag directory ``dst``.

    Raises BagReadError for a bag that cannot be read at all, BagWriteError if ``dst``
    exists.
    """
    out = Path(dst)
    if out.exists():
        msg = f'{out} already exists: give a new directory for the reindexed bag'
        raise BagWriteError(msg)
    with open_bag(src, require_joint_states=False) as bag:
        reason = bag.truncation_reason or 'complete (not cut short)'
        custom = dict((bag.metadata or {}).get('custom_data') or {})
        custom.update({'reindexed_from': str(Path(src)), 'reindex_reason': reason})
        n = 0
        try:
            with BagWriter(out, custom_data={str(k): str(v) for k, v in custom.items()}) as w:
                for t in bag.topics.values():
                    w.add_topic(t.name, t.msgtype, _qos(t.offered_qos_profiles),
                                type_hash=t.type_hash)
                for name, items in bag.metadata_records():
                    if name not in _RESERVED and name != REINDEXED:
                        w.add_metadata(name, items)
                w.add_metadata(REINDEXED, {'source': str(Path(src)), 'reason': reason})
                for topic, log_time, data in bag.messages():
                    w.write(topic, log_time, data)
                    n += 1
        except BaseException:
            shutil.rmtree(out, ignore_errors=True)  # no half copy left behind
            raise
        return ReindexResult(out, n, len(bag.topics), reason)


__all__ = ['REINDEXED', 'ReindexResult', 'reindex']
