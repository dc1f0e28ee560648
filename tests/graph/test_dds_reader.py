"""The graph's Fast DDS profile lets a reader hold as many untaken samples as its depth.

Fast DDS caps a reader's history at 5000 samples whatever the subscription's depth: the
recorder (RECORD_DEPTH deep), whose main thread yields to the real-time control path,
kept the first 5000 samples of a topic and silently lost the rest (hexapod_common/runtime/
dds_profile.py, READER_MAX_SAMPLES). A real publisher and a real subscription in a fresh
process with the profile: the subscription takes nothing while more than 5000 samples
arrive, then takes them all.
"""
from __future__ import annotations

import os
import subprocess
import sys

from hexapod_common.core.topics import RECORD_DEPTH
from hexapod_common.runtime.dds_profile import private_profile

from .conftest import next_domain_id

SCRIPT = r"""
import sys, time
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

depth, n = int(sys.argv[1]), int(sys.argv[2])
rclpy.init()
node = rclpy.create_node("reader_limits")
got = []
qos = QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE,
                 history=HistoryPolicy.KEEP_LAST)
node.create_subscription(String, "/reader_limits", lambda m: got.append(int(m.data)), qos)
pub = node.create_publisher(String, "/reader_limits", QoSProfile(
    depth=n, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST))
end = time.monotonic() + 30
while pub.get_subscription_count() < 1 and time.monotonic() < end:
    time.sleep(0.05)
for i in range(n):  # nothing is taken meanwhile
    pub.publish(String(data=str(i)))
time.sleep(1.0)
ex = SingleThreadedExecutor()
ex.add_node(node)
end = time.monotonic() + 30
while len(got) < min(n, depth) and time.monotonic() < end:
    ex.spin_once(timeout_sec=0.05)
print(len(got), got[0] if got else -1, got[-1] if got else -1)
"""


def _received(tmp_path, depth: int, n: int) -> tuple[int, int, int]:
    folder = tmp_path / f"depth{depth}"
    folder.mkdir()
    env = {**os.environ, "ROS_DOMAIN_ID": str(next_domain_id()),
           "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
           "FASTRTPS_DEFAULT_PROFILES_FILE": str(private_profile(folder)),
           "RMW_FASTRTPS_PUBLICATION_MODE": "SYNCHRONOUS"}
    done = subprocess.run([sys.executable, "-c", SCRIPT, str(depth), str(n)], env=env,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    count, first, last = (int(x) for x in done.stdout.split())
    return count, first, last


def test_a_recorder_deep_reader_keeps_every_untaken_sample(tmp_path):
    n = 8000  # more than Fast DDS's default cap (5000), less than RECORD_DEPTH
    assert 5000 < n <= RECORD_DEPTH
    assert _received(tmp_path, RECORD_DEPTH, n) == (n, 0, n - 1)


def test_a_shallow_reader_keeps_the_newest_samples(tmp_path):
    assert _received(tmp_path, 200, 1000) == (200, 800, 999)
