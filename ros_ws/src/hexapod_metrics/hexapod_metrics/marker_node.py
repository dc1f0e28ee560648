"""Node ``markers``: the robot as ``visualization_msgs/MarkerArray`` for Foxglove's 3-D panel.

Listens to the sim's state topics and, every ``1/rate`` s of *simulated* time (default
30 Hz), publishes ``/hexapod/markers`` in frame ``world`` (x forward, z up, the model's y
drawn as z; left legs at +0.5 m, right legs at -0.5 m): legs as line lists, the body as a
line strip, feet in contact as spheres and ground reaction forces as arrows. The metrics
node records the topic like any other, so a bag opened in Foxglove shows the robot walking.
The geometry is :func:`hexapod_metrics.core.figure.stick_figure`, the same as ``hexapod
animate`` draws.
"""
from __future__ import annotations

import sys
import time

import numpy as np
from builtin_interfaces.msg import Duration as DurationMsg
from geometry_msgs.msg import Point
from hexapod_common.core import topics as T
from hexapod_common.core.layout import OBS_SHAPE
from hexapod_common.runtime.hot_loop import HotLoop
from hexapod_common.runtime.input_guard import InputGuard
from hexapod_common.runtime.node_main import run_node
from hexapod_common.runtime.param_topic import ParamAnnouncer
from hexapod_common.runtime.ros_params import declare_node_param, declare_params
from hexapod_common.runtime.rt_sched import use_rt_priority
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from hexapod_common.runtime import conversions as C
from hexapod_common.runtime import inputs_matched

from .core.figure import FORCE_SCALE, side, stick_figure

STATE = (T.JOINT_STATES, T.FOOT_FORCES, T.HIP_STATES)


def _point(x: float, y: float, lateral: float) -> Point:
    return Point(x=float(x), y=float(lateral), z=float(y))


def _color(r: float, g: float, b: float, a: float = 1.0) -> ColorRGBA:
    return ColorRGBA(r=r, g=g, b=b, a=a)


def markers(obs: np.ndarray, l1: float, stamp_ns: int, frame: str = "world") -> MarkerArray:
    """The MarkerArray of one observation (9, 6, 2)."""
    f = stick_figure(obs, l1)
    stamp = C.to_time(stamp_ns)
    life = DurationMsg(sec=0, nanosec=0)

    def base(mid: int, kind: int, ns: str) -> Marker:
        m = Marker()
        m.header.stamp = stamp
        m.header.frame_id = frame
        m.ns, m.id, m.type, m.action = ns, mid, kind, Marker.ADD
        m.pose.orientation.w = 1.0
        m.lifetime = life
        return m

    legs = base(0, Marker.LINE_LIST, "legs")
    legs.scale.x = 0.05
    legs.color = _color(0.2, 0.4, 0.9)
    for i in range(6):
        y = side(i)
        pts = [f.hip[i], f.knee[i], f.knee[i], f.foot[i]]
        legs.points += [_point(p[0], p[1], y) for p in pts]
    body = base(1, Marker.LINE_LIST, "body")
    body.scale.x = 0.08
    body.color = _color(0.1, 0.1, 0.1)
    for a, b in ((0, 1), (2, 3), (4, 5), (0, 2), (2, 4), (1, 3), (3, 5)):
        body.points += [_point(*f.hip[a], side(a)), _point(*f.hip[b], side(b))]
    feet = base(2, Marker.SPHERE_LIST, "contacts")
    feet.scale.x = feet.scale.y = feet.scale.z = 0.1
    feet.color = _color(0.9, 0.1, 0.1)
    feet.points = [_point(*f.foot[i], side(i)) for i in range(6) if f.contact[i]]
    out = MarkerArray(markers=[legs, body, feet])
    for i in range(6):
        arrow = base(10 + i, Marker.ARROW, "forces")
        arrow.scale.x, arrow.scale.y, arrow.scale.z = 0.03, 0.06, 0.1
        arrow.color = _color(0.9, 0.5, 0.0)
        if f.contact[i]:
            tip = f.foot[i] + f.force[i] * FORCE_SCALE
            arrow.points = [_point(*f.foot[i], side(i)), _point(*tip, side(i))]
        else:
            arrow.action = Marker.DELETE
        out.markers.append(arrow)
    return out


class MarkerNode(Node):
    """Publishes the robot's markers at ``rate`` Hz of simulated time."""

    def __init__(self) -> None:
        super().__init__("markers")
        p = declare_params(self)  # the shared params file (--ros-args --params-file)
        rate = declare_node_param(self, "rate")
        self.l1 = p.robot.leg_length_1
        self.period_ns = int(round(p.sim.control_period * 1e9))
        self.stride = max(1, int(round(1.0 / (rate * p.sim.control_period))))
        self.pending: dict[int, dict[str, np.ndarray]] = {}
        self.guard = InputGuard(self, self.get_logger())
        self.loop = HotLoop(self)
        inputs_matched.offer(self, self.loop.subscriptions, self.guard)  # asked before tick 0
        self.pub = self.create_publisher(MarkerArray, T.MARKERS,
                                         C.TOPIC_QOS[T.MARKERS].publisher())
        self.signer = self.guard.signer(T.MARKERS)
        deliver_to = declare_node_param(self, "deliver_to")
        timeout = declare_node_param(self, "startup_timeout")
        # Its Fast DDS threads under SCHED_FIFO when asked (runtime/rt_sched.py).
        self.rt = use_rt_priority(self, self.get_logger(), main=False)
        # The sim's tick 0 waits for this node's state subscriptions; they are made only once
        # the recorder's subscription is matched, or the first markers are published to
        # nobody (a volatile writer does not keep them for a reader it matches later).
        self._wait_for_readers([n.strip() for n in deliver_to.split(",") if n.strip()],
                               timeout)
        for topic in STATE:
            # Deep queues: a marker for every 1/rate s of sim time, even when this node
            # falls behind the sim for a while (a short queue rolled over: gaps of 66-264 ms).
            self.loop.subscribe(JointState, topic, self._make_cb(topic),
                                C.TOPIC_QOS[topic].subscriber(C.RECORD_DEPTH))
        self.announcer = ParamAnnouncer(self, p.sim.control_period)

    def _readers_missing(self, nodes: list[str]) -> list[str]:
        infos = self.get_subscriptions_info_by_topic(T.MARKERS)
        missing = [n for n in nodes if not any(i.node_name == n for i in infos)]
        if not missing and self.pub.get_subscription_count() < len(infos):
            missing.append(f"matching of {T.MARKERS}")
        return missing

    def _wait_for_readers(self, nodes: list[str], timeout: float) -> None:
        """Block (wall s, at most ``timeout``) until ``nodes`` subscribe to the markers and
        this node's publisher has matched every subscription the graph shows."""
        deadline = time.monotonic() + timeout
        while (missing := self._readers_missing(nodes)) and time.monotonic() < deadline:
            time.sleep(0.01)
        if missing:
            self.get_logger().warning(f"starting without {', '.join(missing)} after "
                                      f"{timeout:g} s: the first markers may not reach them")

    def _make_cb(self, topic: str):  # type: ignore[no-untyped-def]
        def cb(data: bytes) -> None:
            view = self.guard.joint_state(topic, data, self.period_ns)
            if view is None:
                return
            k = C.tick_of(view.stamp_ns, self.period_ns)
            if k % self.stride:
                return
            got = self.pending.setdefault(k, {})
            got[topic] = (view.position.copy(), view.velocity.copy(), view.effort.copy())
            if len(got) == len(STATE):
                obs = np.empty(OBS_SHAPE)
                for name, arrays in got.items():
                    C.fill_obs(obs, name, *arrays)
                self.pub.publish(self.guard.signed(self.signer,
                                                   markers(obs, self.l1, k * self.period_ns)))
                for old in [j for j in self.pending if j <= k]:
                    del self.pending[old]
        return cb


def main(args: list[str] | None = None) -> int:
    """Entry point of ``markers``."""
    return run_node("markers", MarkerNode, args)


if __name__ == "__main__":
    sys.exit(main())
