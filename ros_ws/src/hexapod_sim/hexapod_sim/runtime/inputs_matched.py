"""Whether a node's readers of the sim's per-tick topics have matched a writer on their own
side: the ``~/inputs_matched`` service (``std_srvs/Trigger``) each subscribing node of the
graph offers, and the sim asks before tick 0.

A writer and a reader match each other independently: each side does so when its process
has taken in the other's announcement. The sim used to start once *its* writers had matched
every reader the graph showed (``SimNode.graph_missing``); in realtime runs at 1 kHz the
recorder's readers matched the sim's writers ~0.2 s later on the recorder's side, and the
samples sent meanwhile were dropped there (a volatile reader takes nothing from a writer it
does not know yet): 2 of 4 bags began at tick ~200. Only the reading node can tell when its
readers have matched, so it answers: ``success`` is true when each of its subscriptions to
a topic of :data:`SIM_TOPICS` has matched at least one writer; ``message`` lists the topics
still waiting (empty when ready). A node with no such subscription (an inactive
controller) is ready.
"""
from __future__ import annotations

from typing import Any, Callable, Iterable

from rclpy.node import Node
from rclpy.service import Service
from rclpy.subscription import Subscription

from ..core import topics as T

#: Name of the service under the node's namespace (``/<node>/inputs_matched``).
SERVICE = "inputs_matched"
#: The topics whose writer is the sim: tick 0 waits until their readers have matched it.
SIM_TOPICS = (T.JOINT_STATES, T.FOOT_FORCES, T.HIP_STATES)


def unmatched(subscriptions: Iterable[Subscription]) -> list[str]:
    """Topics of :data:`SIM_TOPICS` among ``subscriptions`` with no matched writer yet."""
    return sorted({s.topic_name for s in subscriptions
                   if s.topic_name in SIM_TOPICS and s.get_publisher_count() < 1})


def offer(node: Node, subscriptions: Callable[[], Iterable[Subscription]]) -> Service:
    """Create ``node``'s ``~/inputs_matched`` service; ``subscriptions()`` gives the node's
    current subscriptions (its hot loop's). Call the loop's ``refresh()`` afterwards."""
    from std_srvs.srv import Trigger

    def answer(request: Any, response: Any) -> Any:
        waiting = unmatched(subscriptions())
        response.success = not waiting
        response.message = ",".join(waiting)
        return response
    return node.create_service(Trigger, f"~/{SERVICE}", answer)


__all__ = ["SERVICE", "SIM_TOPICS", "offer", "unmatched"]
