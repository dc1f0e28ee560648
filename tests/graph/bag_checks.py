"""Checks of a graph bag with independent readers (rosbags, the mcap library)."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from hexapod_metrics.core.recording import TICK_TOPICS
from hexapod_common.core.params import NODE_PARAMS

MS = 1_000_000


def mcap_file(bag: Path) -> Path:
    """The bag's only MCAP file."""
    files = sorted(bag.glob("*.mcap"))
    assert len(files) == 1, files
    return files[0]


def mcap_size(bag: Path) -> int:
    """Size of the bag's MCAP file (0 before it exists)."""
    files = list(bag.glob("*.mcap"))
    return files[0].stat().st_size if files else 0


def read_with_mcap(path: Path) -> dict[str, Any]:
    """Everything the mcap library's seeking reader says about one MCAP file."""
    from mcap.reader import SeekingReader

    with open(path, "rb") as fh:
        reader = SeekingReader(fh, validate_crcs=True)
        summary = reader.get_summary()
        assert summary is not None, f"{path.name}: no summary (not indexed)"
        channels = {c.id: c.topic for c in summary.channels.values()}
        stats = {channels[c]: n for c, n in summary.statistics.channel_message_counts.items()}
        writer = {m.name: m.metadata for m in reader.iter_metadata()}
        file_order = [(c.topic, m.log_time, m.data)
                      for _, c, m in reader.iter_messages(log_time_order=False)]
        chunks = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
        last = chunks[-1] if chunks else None
    return {"stats": stats, "metadata": writer, "messages": file_order, "last_chunk": last}


def read_with_rosbags(bag: Path) -> list[tuple[str, int, Any]]:
    """(topic, log time, decoded message) of every message, as rosbags yields them."""
    from rosbags.highlevel import AnyReader

    with AnyReader([bag]) as reader:
        return [(c.topic, t, reader.deserialize(raw, c.msgtype))
                for c, t, raw in reader.messages()]


def metadata_counts(bag: Path) -> dict[str, int]:
    """Per-topic message counts of metadata.yaml."""
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    return {t["topic_metadata"]["name"]: t["message_count"]
            for t in info["topics_with_message_count"]}


#: Tick topics the sim itself publishes: one message per tick, whatever the controller does.
SIM_TOPICS = ("/clock", "/hexapod/joint_states", "/hexapod/foot_forces", "/hexapod/hip_states")


#: Sim time after a late-joining recorder's first joint state from which its tick topics
#: must have no gap (see ``joined_late``).
JOIN_SETTLE_NS = 500 * MS


def check_indexed_ordered_bag(bag: Path, missed: int = 0, joined_late: bool = False
                              ) -> dict[str, list[int]]:
    """Assert what R11 asks of a bag, killed or not; return the tick topics' stamps (ns).

    ``missed``: ticks the sim counted as missed (no command in time): the commands and the
    reference may lack that many ticks, the sim's own topics none.

    ``joined_late``: the recorder joined a running graph. Its first messages are the
    transient-local backlog of the reference and the commands (5000 ticks each, older than
    its first state) and the first ticks of each topic as its endpoints match one by one;
    that start may have holes (seen: 1-3 reference ticks at the oldest end of the backlog,
    which the writer's history rolls past while delivering it; once 9 /clock ticks 90 ms
    after the recorder's first state). From ``JOIN_SETTLE_NS`` after its first joint state
    on, every tick must be there; order, ends, counts and indexes are checked throughout."""
    seen = read_with_mcap(mcap_file(bag))
    messages = seen["messages"]
    assert messages, f"{bag}: no message"
    late = int(seen["metadata"]["hexapod_writer"]["late_messages"])
    steps_back = sum(1 for (_, a, _), (_, b, _) in zip(messages, messages[1:]) if b < a)
    assert steps_back <= late, f"{steps_back} steps back in file order, {late} late messages"
    by_topic: dict[str, list[int]] = {}
    for topic, log_time, _ in messages:
        by_topic.setdefault(topic, []).append(log_time)
    settled = by_topic["/hexapod/joint_states"][0] + JOIN_SETTLE_NS if joined_late else 0
    for topic in TICK_TOPICS:  # each tick topic in order, one message per tick
        stamps = by_topic[topic]
        assert all(b > a for a, b in zip(stamps, stamps[1:])), f"{topic} out of order"
        gaps = [(a, b) for a, b in zip(stamps, stamps[1:]) if b - a != MS and b > settled]
        lost = sum((b - a) // MS - 1 for a, b in gaps)
        allowed = 0 if topic in SIM_TOPICS else missed
        assert lost <= allowed, f"{topic}: {lost} ticks missing ({gaps[:3]}), {allowed} missed"
    ends = {t: by_topic[t][-1] for t in TICK_TOPICS if t != "/hexapod/reference"}
    assert len(set(ends.values())) == 1, f"tick topics end at different ticks: {ends}"
    # the references run up to the trajectory generator's lookahead ahead of the states
    lookahead = NODE_PARAMS["trajectory_generator"]["lookahead"].default
    assert 0 <= by_topic["/hexapod/reference"][-1] - next(iter(ends.values())) <= lookahead * MS
    assert {t: len(v) for t, v in by_topic.items()} == {
        t: n for t, n in seen["stats"].items() if n}
    # rosbags reads the same messages (indexed, so in log-time order)
    rb = read_with_rosbags(bag)
    assert len(rb) == len(messages)
    assert all(b >= a for (_, a, _), (_, b, _) in zip(rb, rb[1:]))
    js = [m for t, _, m in rb if t == "/hexapod/joint_states"]
    assert len(js) == len(by_topic["/hexapod/joint_states"])
    # metadata.yaml lags the MCAP by at most its last chunk
    listed = metadata_counts(bag)
    last = seen["last_chunk"]
    in_last: dict[str, int] = {}
    for topic, log_time, _ in messages:
        if last.message_start_time <= log_time <= last.message_end_time:
            in_last[topic] = in_last.get(topic, 0) + 1
    for topic, n in seen["stats"].items():
        assert n - in_last.get(topic, 0) <= listed.get(topic, 0) <= n, (topic, n, listed)
    return {t: by_topic[t] for t in TICK_TOPICS}


def bag_qos(bag: Path) -> dict[str, str]:
    """topic -> durability of the offered QoS in metadata.yaml and in the MCAP's channels
    (read by rosbags), which must agree."""
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    out = {}
    for t in meta["topics_with_message_count"]:
        md = t["topic_metadata"]
        qos = md["offered_qos_profiles"]
        if isinstance(qos, str):
            qos = yaml.safe_load(qos)
        durability = {q["durability"] for q in qos}
        assert len(durability) == 1, md
        d = durability.pop()
        out[md["name"]] = "transient_local" if d in ("transient_local", 1) else "reliable"
    from rosbags.highlevel import AnyReader

    with AnyReader([bag]) as reader:
        for c in reader.connections:
            want = out[c.topic]
            durability = {str(q.durability).lower() for q in c.ext.offered_qos_profiles}
            assert any(want.split("_")[0] in d for d in durability) or (
                want == "reliable" and any("volatile" in d for d in durability)), (c, want)
    return out


def recorded_obs(bag: Any, ticks: int, period_ns: int) -> Any:
    """The samples (ticks, 9, 6, 2) of an open bag's three state topics, after asserting that
    each holds exactly ticks 0 .. ticks - 1 (stamps k * period_ns)."""
    import numpy as np

    from hexapod_common.core import topics as T
    from hexapod_metrics.bag import read_joint_state_arrays

    cols = {}
    for topic in T.STATE_TOPICS:
        a = read_joint_state_arrays(bag, topic)
        assert np.array_equal(a.stamps, np.arange(ticks) * period_ns), f"{topic}: a tick is missing"
        cols[topic] = (a.position, a.velocity, a.effort)
    return T.obs_from_columns(cols)
