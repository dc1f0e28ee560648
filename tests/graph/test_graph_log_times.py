"""In a graph bag every message is logged at its own sim time, and our decoder reads the
DDS-padded strings and statuses the graph produces (issue 9, builds 3 and 5).

One lockstep run with both controllers, a scripted switch at 1 s and the markers node.
Checked with rosbags (an independent decoder) against the log times the MCAP holds.
"""
from __future__ import annotations

import pytest

from hexapod_common.core import cdr
from hexapod_common.core import topics as T

from .bag_checks import MS, check_indexed_ordered_bag, read_with_rosbags

#: One worker runs the module (its module-scoped fixture once): scripts/test.sh uses
#: pytest-xdist's loadgroup distribution.
pytestmark = pytest.mark.xdist_group("test_graph_log_times")

DURATION, SWITCH_AT = 2.5, 1.0
STRIDE = 33 * MS  # markers at 30 Hz of sim time with 1 kHz control
STAMPED = (T.CLOCK, T.JOINT_STATES, T.FOOT_FORCES, T.HIP_STATES, T.REFERENCE,
           T.JOINT_COMMANDS, T.STATUS, T.INDICES)


def _stamp(msg) -> int:
    t = msg.clock if hasattr(msg, "clock") else msg.header.stamp
    return int(t.sec) * 1_000_000_000 + int(t.nanosec)


@pytest.fixture(scope="module")
def graph_bag(tmp_path_factory):
    from hexapod_bringup.cmd_graph import GraphProcesses

    from .conftest import FAST_TIMING, STOP_ORDER, next_domain_id

    tmp = tmp_path_factory.mktemp("logtimes")
    bag = tmp / "bag"
    g = GraphProcesses(tmp / "logs", env={"ROS_DOMAIN_ID": str(next_domain_id()),
                                          "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"},
                       overrides=FAST_TIMING)  # 1 kHz control: 1 ms ticks
    try:
        g.start("metrics", f"bag_path:={bag}")
        for name in ("trajectory_generator", "pd_p_controller", "pd_pf_controller",
                     "markers"):
            g.start(name)
        g.start("hexapod_sim", "wait_for:=trajectory_generator,pd_p_controller,"
                "pd_pf_controller,metrics,markers", f"run.duration:={DURATION}",
                "stop_at_end:=true", f"switch_at:={SWITCH_AT}", "switch_to:=pd_p")
        assert g.wait_exit("hexapod_sim", 600) == 0
    finally:
        codes = g.stop_all(order=(*STOP_ORDER, "markers"))
    assert codes["metrics"] == 0, g.log("metrics")[-2000:]
    return bag, read_with_rosbags(bag)


def test_log_time_is_the_message_stamp_on_every_stamped_topic(graph_bag):
    bag, messages = graph_bag
    check_indexed_ordered_bag(bag)
    seen = {t: 0 for t in STAMPED}
    for topic, log_time, msg in messages:
        if topic in seen:
            assert log_time == _stamp(msg), (topic, log_time, _stamp(msg))
            seen[topic] += 1
    assert all(seen.values()), seen
    assert seen[T.JOINT_STATES] == round(DURATION * 1000) + 1


def test_markers_cover_the_run_from_zero_without_gaps(graph_bag):
    _, messages = graph_bag
    markers = [(t, m) for topic, t, m in messages if topic == T.MARKERS]
    assert markers
    for log_time, msg in markers:
        assert log_time == _stamp(msg.markers[0])
    stamps = [t for t, _ in markers]
    assert stamps[0] == 0
    assert all(b - a == STRIDE for a, b in zip(stamps, stamps[1:])), "a gap in the markers"
    assert stamps[-1] > DURATION * 1e9 - STRIDE


def test_active_controller_is_logged_at_the_tick_of_its_switch(graph_bag):
    _, messages = graph_bag
    first_tick: dict[str, int] = {}
    for topic, t, msg in messages:
        if topic == T.JOINT_STATES:
            first_tick.setdefault(msg.header.frame_id, t)
    switches = [(t, m.data) for topic, t, m in messages if topic == T.ACTIVE_CONTROLLER]
    assert switches == [(0, "pd_pf"), (round(SWITCH_AT * 1e9), "pd_p")]
    assert all(first_tick[who] == t for t, who in switches)


def test_padded_strings_and_statuses_decode_like_rosbags(graph_bag):
    bag, messages = graph_bag
    from mcap.reader import make_reader

    from .bag_checks import mcap_file

    raw = {}
    with open(mcap_file(bag), "rb") as fh:
        for _, channel, m in make_reader(fh).iter_messages(
                topics=[T.ACTIVE_CONTROLLER, T.STATUS, T.INDICES]):
            raw[(channel.topic, m.log_time, m.sequence)] = m.data
    decoded = [(k[0], d) for k, d in sorted(raw.items(), key=lambda kv: kv[0][1:])]
    theirs = [(t, m) for t, _, m in messages if t in (T.ACTIVE_CONTROLLER, T.STATUS, T.INDICES)]
    assert len(decoded) == len(theirs)
    padded = 0
    by_topic: dict[str, list] = {}
    for topic, m in theirs:
        by_topic.setdefault(topic, []).append(m)
    for topic, data in decoded:
        ref = by_topic[topic].pop(0) if topic == T.ACTIVE_CONTROLLER else None
        # DDS pads a sample to 4 bytes; the recorder stores what the signed sample carried
        # without its trailer, so pad it again as a plain DDS writer would have sent it.
        dds = data + b"\0" * (-len(data) % 4)
        padded += len(dds) > len(data)
        if topic == T.ACTIVE_CONTROLLER:
            text = cdr.decode_string(dds)
            assert text == ref.data == cdr.decode_string(data)
        else:
            stamp, statuses = cdr.decode_diagnostic_array(dds)
            assert statuses and all(s.name for s in statuses)
            assert (stamp, statuses) == cdr.decode_diagnostic_array(data)
    assert padded > 0, "no message needed DDS padding: the test proves nothing"
    # and the statuses equal rosbags' decoding, field by field
    for topic in (T.STATUS, T.INDICES):
        ours = [cdr.decode_diagnostic_array(d) for t, d in decoded if t == topic]
        ref = [m for t, m in theirs if t == topic]
        assert [[(s.name, s.message, s.values) for s in st] for _, st in ours] == [
            [(s.name, s.message, tuple((kv.key, kv.value) for kv in s.values))
             for s in m.status] for m in ref]
