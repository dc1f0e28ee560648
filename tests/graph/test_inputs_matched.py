"""The ``inputs_matched`` service a reading node offers the sim before tick 0.

Tick 0 waits until the readers of the sim's topics have matched its writers on their own
side (hexapod_common/runtime/inputs_matched.py). Real rclpy endpoints in a fresh process with
the graph's Fast DDS profile: a node reading joint states and references answers "not
matched" naming the joint states while no one publishes them (a reference publisher does
not count: the sim does not write references), then "matched" once a joint-state writer
has matched on its side, counting the writers its command and reference readers matched;
a node without such a reader is ready at once, and one that writes commands counts the
readers its writer matched. Answers carry the
run key's tag: an impostor's answer (no key), a genuine answer with its flag flipped,
moved to another node or replayed, and garbage (empty, no tag, a tag that is not hex, a
zero tag, 100 kB of text, odd characters) are dropped and counted. The graph-level case (the sim
does not start early on an impostor's word) is test_an_impostor_cannot_start_the_run.
"""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys

from hexapod_common.core.msg_auth import new_key_file
from hexapod_common.runtime.dds_profile import private_profile

from .conftest import next_domain_id

SCRIPT = r"""
import json, time
import rclpy
from rclpy.executors import SingleThreadedExecutor
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger
from hexapod_common.core import topics as T
from hexapod_common.runtime import conversions as C
from hexapod_common.runtime import inputs_matched

from hexapod_common.runtime.input_guard import InputGuard

rclpy.init()
reader = rclpy.create_node("metrics")
subs = [reader.create_subscription(JointState, t, lambda m: None,
                                   C.TOPIC_QOS[t].subscriber(10), raw=True)
        for t in (T.JOINT_STATES, T.REFERENCE, T.JOINT_COMMANDS)]
inputs_matched.offer(reader, lambda: subs, InputGuard(reader, reader.get_logger()))
idle = rclpy.create_node("pd_p_controller")
idle_subs = [idle.create_subscription(JointState, T.REFERENCE, lambda m: None,
                                      C.TOPIC_QOS[T.REFERENCE].subscriber(10), raw=True)]
inputs_matched.offer(idle, lambda: idle_subs, InputGuard(idle, idle.get_logger()))
impostor = rclpy.create_node("markers")  # no key: answers "ready" in plain text

def forged(request, response):
    response.success, response.message = True, ""
    return response
impostor.create_service(Trigger, inputs_matched.service_name("markers"), forged)
asker = rclpy.create_node("asker")
guard = InputGuard(asker, asker.get_logger())
ex = SingleThreadedExecutor()
for n in (reader, idle, impostor, asker):
    ex.add_node(n)
raw = {}

def ask(name):
    client = asker.create_client(Trigger, inputs_matched.service_name(name))
    end = time.monotonic() + 30
    while not client.service_is_ready() and time.monotonic() < end:
        ex.spin_once(timeout_sec=0.05)
    future = client.call_async(Trigger.Request())
    ex.spin_until_future_complete(future, timeout_sec=30)
    res = future.result()
    raw[name] = (res.success, res.message)
    return [res.success, inputs_matched.opened(guard, name, res.success, res.message)]

out = {"before": ask("metrics")}
success, message = raw["metrics"]
out["flipped"] = inputs_matched.opened(guard, "metrics", not success, message)
out["moved"] = inputs_matched.opened(guard, "pd_pf_controller", success, message)
out["replayed"] = inputs_matched.opened(guard, "metrics", success, message)
out["garbage"] = [inputs_matched.opened(guard, "metrics", True, m) for m in (
    "", "|", "x|zz", "|" + "00" * 32, "a" * 100000 + "|" + "ff" * 32, "\x00|\u00e9")]
out["idle"] = ask("pd_p_controller")
out["impostor"] = ask("markers")
out["drops"] = guard.drops.values()
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
commander = rclpy.create_node("commander")  # a controller: it writes commands
cmd_pub = commander.create_publisher(JointState, T.JOINT_COMMANDS,
                                     C.TOPIC_QOS[T.JOINT_COMMANDS].publisher())
inputs_matched.offer(commander, lambda: [], InputGuard(commander, commander.get_logger()),
                     lambda: [cmd_pub])
ex.add_node(commander)
end = time.monotonic() + 30
while cmd_pub.get_subscription_count() < 1 and time.monotonic() < end:
    ex.spin_once(timeout_sec=0.05)
out["commander"] = ask("commander")
print(json.dumps(out))
"""


def test_a_reader_is_ready_once_its_sim_topics_have_matched_a_writer(tmp_path):
    env = {**os.environ, "ROS_DOMAIN_ID": str(next_domain_id()), "HEXAPOD_AUTH": "on",
           "HEXAPOD_KEY_FILE": str(new_key_file(tmp_path)),
           "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
           "FASTRTPS_DEFAULT_PROFILES_FILE": str(private_profile(tmp_path))}
    done = subprocess.run([sys.executable, "-c", SCRIPT], env=env, capture_output=True,
                          text=True, timeout=180)
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout.strip().splitlines()[-1])
    drops = out.pop("drops")
    assert out == {"before": [False, "/hexapod/joint_states"],
                   "flipped": None, "moved": None, "replayed": None,
                   "garbage": [None] * 6,
                   "idle": [True, "/hexapod/reference=0"],  # ready, its reader counted
                   "impostor": [True, None],
                   "reference_only": [False, "/hexapod/joint_states"],
                   "after": [True, "/hexapod/joint_commands=0,/hexapod/reference=1"],
                   # its command writer has matched the reader of "metrics" on its side
                   "commander": [True, "writer:/hexapod/joint_commands=1"]}
    assert drops == {"dropped": "10",
                     "dropped /markers/inputs_matched (unauthenticated)": "1",
                     "dropped /metrics/inputs_matched (unauthenticated)": "7",  # flipped, garbage
                     "dropped /pd_pf_controller/inputs_matched (unauthenticated)": "1",
                     "dropped /metrics/inputs_matched (replayed)": "1"}


IMPOSTOR = r"""
import signal
import rclpy
from rclpy.executors import SingleThreadedExecutor
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger
from hexapod_common.runtime import conversions as C
from hexapod_common.runtime import inputs_matched

rclpy.init()
node = rclpy.create_node("markers")  # the markers node's name, without the run's key
subs = [node.create_subscription(JointState, t, lambda m: None,
                                 C.TOPIC_QOS[t].subscriber(10), raw=True)
        for t in inputs_matched.SIM_TOPICS]
asked = [0]

def forged(request, response):
    asked[0] += 1
    response.success, response.message = True, ""
    return response
node.create_service(Trigger, inputs_matched.service_name("markers"), forged)
stop = []
signal.signal(signal.SIGTERM, lambda *a: stop.append(1))
ex = SingleThreadedExecutor()
ex.add_node(node)
while not stop:
    ex.spin_once(timeout_sec=0.05)
print(f"impostor: asked {asked[0]} times", flush=True)
"""


def test_an_impostor_cannot_start_the_run(make_graph, tmp_path):
    """A process without the run's key, named like the markers node and offering its
    ``inputs_matched`` service, says "ready" at once: the sim drops every such answer
    (counted, named in its log) and starts only after INPUTS_TIMEOUT, with an error naming
    markers, as when the real node's readers do not match."""
    from hexapod_common.core.msg_auth import KEY_ENV

    g = make_graph()
    for n in ("trajectory_generator", "pd_p_controller", "pd_pf_controller"):
        g.start(n)
    env = {k: v for k, v in g.env.items() if k != KEY_ENV}
    with open(tmp_path / "impostor.log", "wb") as log:
        impostor = subprocess.Popen([sys.executable, "-c", IMPOSTOR], env=env, stdout=log,
                                    stderr=subprocess.STDOUT, start_new_session=True)
    try:
        g.start("hexapod_sim", "run.duration:=0.5", "stop_at_end:=true",
                "wait_for:=trajectory_generator,pd_p_controller,pd_pf_controller,markers")
        assert g.wait_exit("hexapod_sim", 600) == 0
    finally:
        impostor.terminate()
        impostor.wait(30)
    sim = g.log("hexapod_sim")
    assert "dropped a message on /markers/inputs_matched: unauthenticated" in sim, sim
    assert "markers: its answers are not authentic (dropped)" in sim, sim
    asked = int((tmp_path / "impostor.log").read_text().split("asked ")[1].split()[0])
    counted = re.search(r"inputs: dropped (\d+) messages: /markers/inputs_matched (\d+) "
                        r"unauthenticated", sim)
    assert counted and counted[1] == counted[2], sim
    assert 1 <= int(counted[1]) <= asked  # every answer it took (one may come after the end)


def test_a_ready_answer_counts_command_writers_and_the_sim_waits_for_all_of_them():
    """A recorder that matched fewer command writers than the sim has is not ready yet: it
    would lose a joined controller's first commands."""
    from hexapod_common.runtime.inputs_matched import behind

    expected = {"/hexapod/joint_commands": 2}
    assert behind("/hexapod/joint_commands=2", expected) == ""
    assert behind("/hexapod/joint_commands=3", expected) == ""
    assert behind("", expected) == ""  # a node without a command reader
    assert behind("/hexapod/joint_commands=1", expected) == (
        "readers of /hexapod/joint_commands matched 1 of 2 writers")
    assert behind("/hexapod/joint_commands=x", expected).startswith("a malformed answer")
    assert behind("/other=0", expected) == ""
    both = {"/hexapod/joint_commands": 1, "/hexapod/reference": 1}
    assert behind("/hexapod/joint_commands=1,/hexapod/reference=0", both) == (
        "readers of /hexapod/reference matched 0 of 1 writers")


def test_a_controllers_answer_counts_its_command_writers_readers_and_the_sim_waits():
    """A controller whose command writer has not matched every command reader the sim sees
    (the recorder's volatile one) on its side is not ready: the recorder would lose its
    first commands (a lockstep bag once lacked PD-P&F's first 106)."""
    from hexapod_common.runtime.inputs_matched import WRITER, behind

    expected = {"/hexapod/joint_commands": 0, WRITER + "/hexapod/joint_commands": 2}
    assert behind("writer:/hexapod/joint_commands=2", expected) == ""
    assert behind("/hexapod/reference=1,writer:/hexapod/joint_commands=1", expected) == (
        "its writer of /hexapod/joint_commands matched 1 of 2 readers")
    assert behind("/hexapod/joint_commands=5", expected) == ""  # a recorder: no writer
