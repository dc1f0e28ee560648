"""Bag writer as a recorder: watermark order, summary after every chunk, records, split
files, full disk; log-time rules; DDS padding in the decoder."""
from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
import pytest
import yaml
from graph.small_disk import small_disk
from hexapod_metrics.bag import (
    RESERVE_NAME,
    BagStorageError,
    BagWriteError,
    BagWriter,
    open_bag,
    read_joint_state_arrays,
)
from hexapod_metrics.core.log_times import ControllerLogTimes, marker_array_stamp
from hexapod_common.core import cdr

from killed_writer import write_then_kill

mcap_reader = pytest.importorskip("mcap.reader", reason="mcap is not installed")
highlevel = pytest.importorskip("rosbags.highlevel", reason="rosbags is not installed")

NAMES = [f"j{i}" for i in range(12)]
A, B, C = "/a", "/b", "/c"
MS = 1_000_000


def _js(t: int) -> bytes:
    row = np.full(12, float(t))
    return cdr.encode_joint_state(t, NAMES, row, row, row)


def _file_order(path: Path) -> list[tuple[str, int]]:
    with open(path, "rb") as fh:
        reader = mcap_reader.SeekingReader(fh, validate_crcs=True)
        assert reader.get_summary() is not None
        return [(c.topic, m.log_time) for _, c, m in reader.iter_messages(log_time_order=False)]


def _writer(path: Path, **kw: object) -> BagWriter:
    w = BagWriter(path, sync_topics=(A, B), chunk_size=8 * 1024, **kw)  # type: ignore[arg-type]
    w.open()
    for topic in (A, B, C):
        w.add_topic(topic, "sensor_msgs/msg/JointState")
    return w


def test_batches_that_step_back_are_written_in_log_time_order(tmp_path: Path) -> None:
    w = _writer(tmp_path / "order", reorder_window_ns=100 * MS)
    # the recorder takes one topic's queue, then the other's: A runs up to 50 ticks ahead,
    # and C (not a tick topic) comes in up to 50 ticks late, within the reorder window
    for start in range(0, 2000, 50):
        for topic in (A, B):
            for k in range(start, start + 50):
                w.write(topic, k * MS, _js(k * MS))
        w.write(C, start * MS, _js(start * MS))
    w.close()
    order = _file_order(tmp_path / "order" / "order_0.mcap")
    times = [t for _, t in order]
    assert times == sorted(times) and len(order) == 2 * 2000 + 40
    assert w.late_messages == 0


def test_a_late_message_is_counted_and_still_ordered_by_indexed_readers(
        tmp_path: Path) -> None:
    w = _writer(tmp_path / "late")
    for k in range(3000):
        w.write(A, k * MS, _js(k * MS))
        w.write(B, k * MS, _js(k * MS))
    w.write(C, 5 * MS, _js(5 * MS))  # far behind the chunks already written
    w.close()
    assert w.late_messages == 1
    with highlevel.AnyReader([tmp_path / "late"]) as reader:
        times = [t for _, t, _ in reader.messages()]
    assert times == sorted(times) and len(times) == 6001


def test_a_dead_tick_topic_stops_holding_the_chunks(tmp_path: Path) -> None:
    w = _writer(tmp_path / "dead", max_lag_ns=200 * MS)
    for k in range(100):
        w.write(B, k * MS, _js(k * MS))
    for k in range(3000):  # B fell silent at tick 99
        w.write(A, k * MS, _js(k * MS))
    size = (tmp_path / "dead" / "dead_0.mcap").stat().st_size
    assert size > 200_000  # chunks were written without B
    w.close()


_KILLED = textwrap.dedent("""
    import sys
    import numpy as np
    from hexapod_common.core import cdr
    from hexapod_metrics.bag import BagWriter
    names = [f'j{i}' for i in range(12)]
    w = BagWriter(sys.argv[1], sync_topics=('/a', '/b'), chunk_size=16 * 1024).open()
    w.add_metadata('params', {'ground.scale': '2.0'})
    k = 0
    while True:
        for topic in ('/b', '/a'):
            for j in range(k, k + 40):
                row = np.full(12, float(j))
                w.write_joint_state(topic, j * 1_000_000, names, row, row, row)
        k += 40
""")


def test_sigkill_leaves_an_indexed_bag_with_its_metadata_records(tmp_path: Path) -> None:
    """Killed between two writes, the writer leaves a complete tail. (A kill inside a write
    leaves a torn one: test_bag_format's killed writer and test_bag_reindex.py; seen here
    when the kill landed anywhere, beside two CPU hogs.)"""
    path = tmp_path / "killed"
    write_then_kill(_KILLED, path, 400_000, between_writes=True)
    mcap_file = path / "killed_0.mcap"
    with open(mcap_file, "rb") as fh:
        reader = mcap_reader.SeekingReader(fh)
        records = {m.name: m.metadata for m in reader.iter_metadata()}
        stats = reader.get_summary().statistics.channel_message_counts
    assert records["params"] == {"ground.scale": "2.0"}
    assert records["hexapod_writer"]["state"] == "open"
    counts = sorted(stats.values())
    assert counts[0] == counts[-1] > 0  # both topics cut at the same tick
    with highlevel.AnyReader([path]) as r:
        times = [t for _, t, _ in r.messages()]
    assert times == sorted(times) and len(times) == sum(counts)
    with open_bag(path) as bag:
        assert bag.truncated and "not closed" in bag.truncation_reason
        assert len(read_joint_state_arrays(bag, "/a").stamps) == counts[0]


def test_split_files_each_open_on_their_own(tmp_path: Path) -> None:
    path = tmp_path / "split"
    w = _writer(path, max_file_size=40_000, reserve_bytes=0)
    for k in range(1500):
        w.write(A, k * MS, _js(k * MS))
        w.write(B, k * MS, _js(k * MS))
    w.close()
    files = w.mcap_paths
    assert len(files) > 3 and set(files) == set(path.glob("*.mcap"))
    total = 0
    for f in files:
        total += len(_file_order(f))
    assert total == 3000
    info = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["relative_file_paths"] == [f.name for f in files]
    assert sum(f["message_count"] for f in info["files"]) == 3000 == info["message_count"]
    with highlevel.AnyReader([path]) as r:
        assert sum(1 for _ in r.messages()) == 3000
    with open_bag(path) as bag:
        assert not bag.truncated
        np.testing.assert_array_equal(read_joint_state_arrays(bag, A).stamps,
                                      np.arange(1500) * MS)


def test_full_disk_closes_the_bag_at_its_last_chunk(tmp_path: Path) -> None:
    with small_disk(tmp_path / "disk", 3 << 20) as disk:
        if disk.kind != "tmpfs":
            pytest.skip("needs a tmpfs (root); the graph test covers the file-size limit")
        path = disk.path / "full"
        w = BagWriter(path, chunk_size=64 * 1024).open()
        assert (path / RESERVE_NAME).stat().st_size == 1 << 20
        k = 0
        with pytest.raises(BagStorageError, match="No space left on device") as err:
            while True:
                w.write_joint_state(A, k * MS, NAMES, np.ones(12), np.ones(12), np.ones(12))
                k += 1
        assert "\n" not in str(err.value) and err.value.reason == "No space left on device"
        lost = w.lost_messages  # the buffered messages, including the one being written
        assert w.closed and w.failure and lost > 0
        with pytest.raises(BagWriteError, match="closed"):
            w.write_joint_state(A, k * MS, NAMES, np.ones(12), np.ones(12), np.ones(12))
        assert w.lost_messages == lost + 1
        assert not (path / RESERVE_NAME).exists()
        with open_bag(path) as bag:
            assert bag.truncated and "No space left" in bag.truncation_reason
            n = len(read_joint_state_arrays(bag, A).stamps)
        assert 1000 < n == k + 1 - lost
        with highlevel.AnyReader([path]) as r:
            assert sum(1 for _ in r.messages()) == n
        info = yaml.safe_load((path / "metadata.yaml").read_text())
        assert info["rosbag2_bagfile_information"]["message_count"] == n


def test_controller_log_time_is_the_tick_its_switch_took_effect() -> None:
    lt = ControllerLogTimes(patience_ns=100 * MS)
    assert lt.on_controller("pd_pf", b"1") == []  # before any state: waits
    assert lt.on_state(0, "pd_pf") == [(0, b"1")]
    assert lt.on_state(MS, "pd_pf") == []
    assert lt.on_state(2 * MS, "pd_p") == []  # the state of the switch tick came first
    assert lt.on_controller("pd_p", b"2") == [(2 * MS, b"2")]
    assert lt.on_controller("pd_pf", b"3") == []  # the message came first
    assert lt.on_state(3 * MS, "pd_p") == []
    assert lt.on_state(4 * MS, "pd_pf") == [(4 * MS, b"3")]
    assert lt.on_controller("pd_pf", b"4") == []  # a switch that never takes effect
    assert lt.on_state(50 * MS, "pd_pf") == []
    assert lt.on_state(105 * MS, "pd_pf") == [(105 * MS, b"4")] and lt.unmatched == 1


def test_marker_array_stamp() -> None:
    assert marker_array_stamp(b"\x00\x01\x00\x00" + bytes(4)) is None
    data = b"\x00\x01\x00\x00" + (1).to_bytes(4, "little") + (2).to_bytes(4, "little") + (
        5).to_bytes(4, "little") + bytes(8)
    assert marker_array_stamp(data) == 2_000_000_005


def test_message_definitions_come_from_the_installed_msg_files() -> None:
    from hexapod_metrics.bag import msgdefs

    js = msgdefs.MESSAGE_TYPES["sensor_msgs/msg/JointState"]
    assert js.definition.startswith(msgdefs._msg_text("sensor_msgs/JointState"))
    assert [x for x in js.definition.splitlines() if x.startswith("MSG: ")] == [
        "MSG: std_msgs/Header", "MSG: builtin_interfaces/Time"]
    marker = msgdefs.MESSAGE_TYPES["visualization_msgs/msg/MarkerArray"].definition
    order = [x[5:] for x in marker.splitlines() if x.startswith("MSG: ")]
    assert order[:3] == ["visualization_msgs/Marker", "builtin_interfaces/Duration",
                         "geometry_msgs/Point"]  # depth first, each level sorted
    assert order.index("std_msgs/Header") + 1 == order.index("builtin_interfaces/Time")
    assert msgdefs.lookup("sensor_msgs/JointState") == js
    assert msgdefs.lookup("no_msgs/msg/Nothing") is None
    with pytest.raises(msgdefs.MessageDefinitionError, match="no_msgs/msg/Nothing.msg not found"):
        msgdefs.load("no_msgs/msg/Nothing")


def test_memory_stays_bounded_as_chunks_pile_up(tmp_path: Path) -> None:
    """R6: what the writer keeps grows with the chunk indexes only (~100 bytes a chunk),
    not with the messages written (it once kept every commit's reorder buffer and tail)."""
    import tracemalloc

    w = _writer(tmp_path / "long")
    msg = _js(0)

    def write(k0: int, k1: int) -> None:
        for k in range(k0, k1):
            for topic in (A, B):
                w.write(topic, k * MS, msg)

    write(0, 2000)
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        write(2000, 12000)  # ~7 MB of messages, ~450 chunks
        grown = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    w.close()
    assert (tmp_path / "long" / "long_0.mcap").stat().st_size > 5_000_000
    assert grown < 500_000, f"the writer kept {grown} bytes over 10000 ticks"
    with open_bag(tmp_path / "long") as bag:
        assert len(read_joint_state_arrays(bag, A).stamps) == 12000
