"""Node ``trajectory_generator``: publishes the reference trajectories on ``/hexapod/reference``.

Its clock is the sim's authenticated ``/hexapod/joint_states``: every ``publish_interval``
wall seconds (default 5 ms) it takes the states queued since, checks the newest (tick k) and
publishes the references not yet published through t_{k+lookahead} (default 50 ticks), so
the controllers have the reference of a tick long before its state arrives, and the node
wakes 200 times a second instead of at every tick (at 1 kHz a wake-up per state cost a
quarter of a core on a 2-core machine that the control loop was short of). The lookahead
must cover the ticks of one interval (50 ticks: 10 kHz of simulated ticks per wall
second); a controller whose reference is late waits for it. ``publish_interval: 0.0``
publishes at every state. Each message is
stamped with the time it is for; its columns are
:func:`hexapod_common.core.topics.reference_columns` of :func:`hexapod_common.core.gait.reference`
(paper eqs. 1-4). References are computed a block of ticks at a time, at the same instants
``k * control period`` as the in-process loop, so the numbers are identical to it.

The publisher is transient-local (see hexapod_common.runtime.conversions.TOPIC_QOS): a controller or
recorder that matches late still receives the recent references.
"""
from __future__ import annotations

import sys
import time

import numpy as np
from hexapod_common.core import msg_checks as M
from hexapod_common.core import topics as T
from hexapod_common.core.gait import Reference, reference
from hexapod_common.runtime.hot_loop import FastLogger, HotLoop
from hexapod_common.runtime.input_guard import InputGuard
from hexapod_common.runtime.node_main import run_node
from hexapod_common.runtime.param_topic import ParamAnnouncer
from hexapod_common.runtime.ros_params import ParamBinding, declare_node_param, declare_params
from hexapod_common.runtime.rt_sched import refresh_once, use_rt_priority
from rclpy.duration import Duration
from rclpy.node import Node
from sensor_msgs.msg import JointState

from hexapod_common.runtime import conversions as C
from hexapod_common.runtime import inputs_matched

BLOCK_TICKS = 250  # references computed per block (~0.4 ms), the next one ahead of need
MAX_GAP = 10000  # ticks of missed clock messages filled in at most


class TrajectoryNode(Node):
    """Reference generator driven by the simulated clock."""

    def __init__(self) -> None:
        super().__init__("trajectory_generator")
        self.log = FastLogger(self.get_logger().name)
        self.guard = InputGuard(self, self.log)
        # The authenticated states are the time source (/clock carries no tag): they may go
        # back (a new run), not leap ahead.
        self.window = M.StampWindow()
        self.binding = ParamBinding(self, declare_params(self))
        self.lookahead = declare_node_param(self, "lookahead")
        self.interval = declare_node_param(self, "publish_interval")
        # Its main and Fast DDS threads under SCHED_FIFO when asked (the launcher does in
        # realtime mode: runtime/rt_sched.py): a controller waits for the reference of its
        # tick, so this node is on the control path although it publishes ahead (with
        # normal scheduling on a machine the 1 kHz graph keeps busy, it ran every 0.2-1.3 s
        # and the controller waited for its reference at almost every tick).
        self.rt = use_rt_priority(self, self.log)
        self.rt_refreshed = False
        p = self.binding.params
        self.period = p.sim.control_period
        self.period_ns = int(round(self.period * 1e9))
        self.codec = C.CODECS[T.REFERENCE]
        self.blocks: dict[int, Reference] = {}
        self.next_tick = 0  # first tick not yet published
        self.guard.publish_status(self.get_name(), lambda: self.window.newest or 0)
        self.loop = HotLoop(self)
        inputs_matched.offer(self, self.loop.subscriptions, self.guard)  # asked before tick 0
        self.pub = self.create_publisher(JointState, T.REFERENCE,
                                         C.TOPIC_QOS[T.REFERENCE].publisher())
        self.signer = self.guard.signer(T.REFERENCE)
        self._reference_of(0)  # warm up (and validate) before the first clock arrives
        # The newest state alone says how far to publish (see _on_clock).
        self.states = self.loop.subscribe(
            JointState, T.JOINT_STATES, self._on_clock,
            C.TOPIC_QOS[T.JOINT_STATES].subscriber(C.CONTROL_DEPTH), wake=self.interval == 0,
            newest=lambda data: self.guard.payload_size(T.JOINT_STATES, data))
        if self.interval > 0:
            self.loop.set_deadline(time.monotonic() + self.interval, self._poll)
        self.announcer = ParamAnnouncer(self, self.period, lambda: self.next_tick)

    def _block(self, b: int) -> Reference:
        ref = self.blocks.get(b)
        if ref is None:
            t = np.arange(b * BLOCK_TICKS, (b + 1) * BLOCK_TICKS) * self.period
            ref = self.blocks[b] = reference(self.binding.params, t)
            for old in [x for x in self.blocks if x < b - 1]:
                del self.blocks[old]
        return ref

    def _reference_of(self, k: int) -> T.Columns:
        ref = self._block(k // BLOCK_TICKS)
        i = k % BLOCK_TICKS
        return T.reference_columns(ref.theta[i], ref.theta_vel[i], ref.hip[i], ref.hip_vel[i],
                                   ref.foot[i], ref.foot_vel[i])

    def _poll(self) -> None:
        """Take the states queued since the last poll (the newest counts), then again in
        ``publish_interval`` s."""
        self.loop.take(self.states)
        self.loop.set_deadline(time.monotonic() + self.interval, self._poll)

    def _on_clock(self, data: bytes) -> bool:
        """A state (the newest taken at a wake-up): publish the references from the first
        not yet published through its tick + lookahead; False if the guard dropped it."""
        got = self.guard.joint_state(T.JOINT_STATES, data, self.period_ns, self.window,
                                     advance=True)
        if got is None:
            return False
        if not self.rt_refreshed:  # every peer matched by now: late receive threads too
            refresh_once(self)
        k = C.tick_of(got.stamp_ns, self.period_ns)
        if k < self.next_tick - self.lookahead - 1:  # the clock went back: a new run
            self.log.info(f"clock went back to tick {k}: restarting the references")
            self.next_tick = k
        # From the first tick not yet published: a clock message lost from a full queue
        # (the sim does not wait for the references while it holds or damps) leaves no gap.
        start = self.next_tick if k - self.next_tick < MAX_GAP else k
        for j in range(max(start, 0), k + self.lookahead + 1):
            c = self._reference_of(j)
            self.pub.publish(self.signer.sign(self.codec.encode(
                T.stamp_ns(j * self.period), "", c.position, c.velocity, c.effort)))
        self.next_tick = max(self.next_tick, k + self.lookahead + 1)
        last = self.next_tick - 1
        if last % BLOCK_TICKS >= BLOCK_TICKS // 2:  # past half a block: prepare the next
            self._block(last // BLOCK_TICKS + 1)
        return True


def _finish(node: TrajectoryNode, code: int) -> int:
    skipped = node.loop.superseded.get(T.JOINT_STATES, 0)
    node.log.info(f"stopping; {skipped} states superseded by a newer one at a take; inputs: "
                  f"{node.guard.summary()}")
    node.pub.wait_for_all_acked(Duration(seconds=1))
    return code


def main(args: list[str] | None = None) -> int:
    """Entry point of ``trajectory_generator``."""
    return run_node("trajectory_generator", TrajectoryNode, args, finish=_finish)


if __name__ == "__main__":
    sys.exit(main())
