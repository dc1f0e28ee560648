"""A full disk is an event, not a crash (issue 9, build 2; R10, R11).

The recorder writes to a small disk (a tmpfs the test mounts, or a file-size limit): when
it fills up, the recorder closes the bag at its last complete chunk, says so on
``/hexapod/status`` (an ERROR status named ``metrics``) and in one log line, and exits with
code 3; the graph goes on; the bag opens in rosbags, the mcap library and our reader.
"""
from __future__ import annotations

import time

from hexapod_metrics.bag import open_bag
from hexapod_metrics.metrics_node import EXIT_RECORDING_FAILED

from .small_disk import small_disk
from .bag_checks import check_indexed_ordered_bag
from .conftest import ros_client, sim_summary

DISK = 12 << 20


def test_full_disk_closes_a_readable_bag_reports_it_and_exits_3(make_graph, tmp_path):
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    with small_disk(tmp_path / "disk", DISK) as disk:
        bag = disk.path / "bag"
        g = make_graph()
        statuses: list = []
        with ros_client(g.domain_id) as node:
            sub = node.create_subscription(
                DiagnosticArray, "/hexapod/status",
                lambda m: statuses.extend(s for s in m.status if s.name == "metrics"
                                          and s.level == b"\x02"),  # ERROR (not heartbeats)
                QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE))
            ex = SingleThreadedExecutor(context=node.context)
            ex.add_node(node)
            g.start("metrics", f"bag_path:={bag}", prefix=disk.prefix)
            # Matched before the run starts: on a loaded machine discovery can take longer
            # than the seconds the disk lasts, and an unmatched reader never gets the ERROR.
            g.wait_for(lambda: ex.spin_once(timeout_sec=0.05) or sub.get_publisher_count() > 0,
                       120, "the recorder's /hexapod/status matched")
            g.start("trajectory_generator")
            g.start("pd_pf_controller")
            g.start("hexapod_sim", "wait_for:=trajectory_generator,pd_pf_controller,metrics")
            deadline = time.monotonic() + 400
            while g.procs["metrics"].poll() is None or not statuses:
                assert time.monotonic() < deadline, "the recorder neither failed nor said so"
                ex.spin_once(timeout_sec=0.1)
            ex.remove_node(node)
            ex.shutdown()
        code = g.wait_exit("metrics", 30)
        log = g.log("metrics")
        assert code == EXIT_RECORDING_FAILED, log[-3000:]
        assert "Traceback" not in log
        lines = [x for x in log.splitlines() if "recording stopped" in x]
        assert len(lines) == 1, log[-3000:]
        why = "No space left on device" if disk.kind == "tmpfs" else "File too large"
        assert why in lines[0]
        (status,) = statuses
        assert status.level == b"\x02" and why in status.message
        values = {kv.key: kv.value for kv in status.values}
        assert values["exit_code"] == "3" and values["reason"] == why
        assert g.procs["hexapod_sim"].poll() is None  # the graph went on
        g.stop("hexapod_sim")
        missed = sim_summary(g.log("hexapod_sim"))["missed"]  # a loaded machine may miss

        stamps = check_indexed_ordered_bag(bag, missed)  # rosbags + mcap, ordered, one end
        with open_bag(bag) as b:
            assert b.truncated and why in b.truncation_reason
            assert b.topics["/hexapod/joint_states"].message_count == len(
                stamps["/hexapod/joint_states"]) > 100
        assert not (bag / ".hexapod_reserve").exists()
        g.stop_all()
