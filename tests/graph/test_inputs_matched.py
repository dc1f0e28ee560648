"""The ``inputs_matched`` service a reading node offers the sim before tick 0.

Tick 0 waits until the readers of the sim's topics have matched its writers on their own
side (hexapod_sim/runtime/inputs_matched.py). Real rclpy endpoints in a fresh process with
the graph's Fast DDS profile: a node reading joint states and references answers "not
matched" naming the joint states while no one publishes them (a reference publisher does
not count: the sim does not write references), then "matched" once a joint-state writer
has matched on its side; a node without such a reader is ready at once.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys

from hexapod_sim.runtime.dds_profile import private_profile

from .conftest import next_domain_id

SCRIPT = r"""
import json, time
import rclpy
from rclpy.executors import SingleThreadedExecutor
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger
from hexapod_sim.core import topics as T
from hexapod_sim.runtime import conversions as C
from hexapod_sim.runtime import inputs_matched

rclpy.init()
reader = rclpy.create_node("metrics")
subs = [reader.create_subscription(JointState, t, lambda m: None,
                                   C.TOPIC_QOS[t].subscriber(10), raw=True)
        for t in (T.JOINT_STATES, T.REFERENCE)]
inputs_matched.offer(reader, lambda: subs)
idle = rclpy.create_node("pd_p_controller")
idle_subs = [idle.create_subscription(JointState, T.REFERENCE, lambda m: None,
                                      C.TOPIC_QOS[T.REFERENCE].subscriber(10), raw=True)]
inputs_matched.offer(idle, lambda: idle_subs)
asker = rclpy.create_node("asker")
ex = SingleThreadedExecutor()
for n in (reader, idle, asker):
    ex.add_node(n)

def ask(name):
    client = asker.create_client(Trigger, f"/{name}/{inputs_matched.SERVICE}")
    end = time.monotonic() + 30
    while not client.service_is_ready() and time.monotonic() < end:
        ex.spin_once(timeout_sec=0.05)
    future = client.call_async(Trigger.Request())
    ex.spin_until_future_complete(future, timeout_sec=30)
    res = future.result()
    return [res.success, res.message]

out = {"before": ask("metrics"), "idle": ask("pd_p_controller")}
writers = rclpy.create_node("writers")
writers.create_publisher(JointState, T.REFERENCE, C.TOPIC_QOS[T.REFERENCE].publisher())
ex.add_node(writers)
end = time.monotonic() + 30
while subs[1].get_publisher_count() < 1 and time.monotonic() < end:
    ex.spin_once(timeout_sec=0.05)
out["reference_only"] = ask("metrics")
writers.create_publisher(JointState, T.JOINT_STATES, C.TOPIC_QOS[T.JOINT_STATES].publisher())
end = time.monotonic() + 30
while subs[0].get_publisher_count() < 1 and time.monotonic() < end:
    ex.spin_once(timeout_sec=0.05)
out["after"] = ask("metrics")
print(json.dumps(out))
"""


def test_a_reader_is_ready_once_its_sim_topics_have_matched_a_writer(tmp_path):
    env = {**os.environ, "ROS_DOMAIN_ID": str(next_domain_id()),
           "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
           "FASTRTPS_DEFAULT_PROFILES_FILE": str(private_profile(tmp_path))}
    done = subprocess.run([sys.executable, "-c", SCRIPT], env=env, capture_output=True,
                          text=True, timeout=180)
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout.strip().splitlines()[-1])
    assert out == {"before": [False, "/hexapod/joint_states"],
                   "idle": [True, ""],
                   "reference_only": [False, "/hexapod/joint_states"],
                   "after": [True, ""]}
