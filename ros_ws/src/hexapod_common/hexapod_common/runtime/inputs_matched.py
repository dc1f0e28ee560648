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
still waiting. A node with no such subscription (an inactive controller) is ready. A ready
node's message counts the writers its readers of :data:`COUNTED_TOPICS` have matched
(``/hexapod/joint_commands=2,/hexapod/reference=1``; empty without such readers): those
writers are the controllers and the trajectory generator, not the sim, and the sim waits
until each count reaches the number of such writers it sees itself (:func:`behind`). A
recorder that matched a joined controller ~60 ms after tick 0 had lost its first commands;
a PD-P&F whose reference reader matched the generator late left tick 0 unanswered for the
0.5 s lockstep timeout (208 ticks held at 10 kHz). A node that writes commands (a
controller) also counts, as ``writer:/hexapod/joint_commands=N``, the readers its command
writer has matched on its side, and the sim waits until that reaches the number of command
readers it sees: the recorder reads commands with a volatile reader (so that a controller
publishing with rclpy's defaults is heard), which gets nothing a writer sent before the
*writer* had matched it, and a lockstep bag once lacked PD-P&F's first 106 commands although
the recorder's reader had matched the controller's writer on the recorder's side.

The answer is authenticated like the graph's messages (core/msg_auth.py): with the run's key
the message ends with ``|`` and the hex trailer of the answer (the success flag and the
text), signed under the service's name (:func:`seal`). The sim drops an answer that does
not verify (:func:`opened`; counted and reported by its input guard like any dropped
message), so a process without the key that offers ``/<node>/inputs_matched`` cannot start
the run before that node's readers have matched.
"""
from __future__ import annotations

from typing import Any, Callable, Iterable, Mapping

from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.service import Service
from rclpy.subscription import Subscription

from hexapod_common.core import topics as T
from ..core.msg_auth import TRAILER_BYTES, Signer, Unsigned
from .input_guard import InputGuard

#: Name of the service under the node's namespace (``/<node>/inputs_matched``).
SERVICE = "inputs_matched"
#: The topics whose writer is the sim: tick 0 waits until their readers have matched it.
SIM_TOPICS = (T.JOINT_STATES, T.FOOT_FORCES, T.HIP_STATES)
#: Topics written by others (the controllers, the trajectory generator) whose readers'
#: matched writers a ready answer counts: tick 0 waits until they have matched as many
#: writers as the sim sees (its command reader's, the graph's reference writers).
COUNTED_TOPICS = (T.JOINT_COMMANDS, T.REFERENCE)
#: Topics whose writer (of the answering node) a ready answer reports, as ``WRITER`` + topic,
#: with the number of readers it has matched: tick 0 waits until that is every reader of the
#: topic the sim sees.
WRITTEN_TOPICS = (T.JOINT_COMMANDS,)
WRITER = "writer:"


def unmatched(subscriptions: Iterable[Subscription]) -> list[str]:
    """Topics of :data:`SIM_TOPICS` among ``subscriptions`` with no matched writer yet."""
    return sorted({s.topic_name for s in subscriptions
                   if s.topic_name in SIM_TOPICS and s.get_publisher_count() < 1})


def counted(subscriptions: Iterable[Subscription],
            publishers: Iterable[Publisher] = ()) -> str:
    """A ready answer's text: ``topic=writers`` of each subscription to a topic of
    :data:`COUNTED_TOPICS` and ``writer:topic=readers`` of each publisher of a topic of
    :data:`WRITTEN_TOPICS`, comma-separated (empty without such endpoints)."""
    items = [f"{s.topic_name}={s.get_publisher_count()}" for s in subscriptions
             if s.topic_name in COUNTED_TOPICS]
    items += [f"{WRITER}{p.topic_name}={p.get_subscription_count()}" for p in publishers
              if p.topic_name in WRITTEN_TOPICS]
    return ",".join(sorted(items))


def behind(text: str, expected: Mapping[str, int]) -> str:
    """Why a ready answer's counts (:func:`counted`'s ``text``) fall short of ``expected``
    writers per topic (readers per ``writer:`` topic); empty if they do not."""
    short = []
    for item in filter(None, text.split(",")):
        topic, _, count = item.partition("=")
        if not count.isdigit():
            return f"a malformed answer ({text[:80]!r})"
        if int(count) < expected.get(topic, 0):
            if topic.startswith(WRITER):
                short.append(f"its writer of {topic[len(WRITER):]} matched {count} of "
                             f"{expected[topic]} readers")
            else:
                short.append(f"readers of {topic} matched {count} of {expected[topic]} "
                             "writers")
    return "; ".join(short)


def service_name(node_name: str) -> str:
    """The service of node ``node_name`` (root namespace), also its authentication topic."""
    return f"/{node_name}/{SERVICE}"


def _payload(success: bool, text: str) -> bytes:
    return f"{int(success)}|{text}".encode()


def seal(signer: Signer | Unsigned, success: bool, text: str) -> str:
    """An answer's message: ``text``, then (authentication on) ``|`` and the hex trailer
    that authenticates ``success`` and ``text``."""
    if isinstance(signer, Unsigned):
        return text
    return f"{text}|{signer.sign(_payload(success, text))[-TRAILER_BYTES:].hex()}"


def opened(guard: InputGuard, name: str, success: bool, message: str) -> str | None:
    """The text of node ``name``'s answer if it is authentic (authentication off: the
    message); None if not (dropped: counted and logged by ``guard``)."""
    if guard.key is None:
        return message
    text, sep, tag = message.rpartition("|")
    try:
        trailer = bytes.fromhex(tag) if sep else b""
    except ValueError:
        trailer = b""
    payload = _payload(success, text)
    data = payload + b"\0" * (-len(payload) % 8) + trailer
    return text if guard.payload(service_name(name), data) is not None else None


def offer(node: Node, subscriptions: Callable[[], Iterable[Subscription]],
          guard: InputGuard,
          publishers: Callable[[], Iterable[Publisher]] = lambda: ()) -> Service:
    """Create ``node``'s ``~/inputs_matched`` service; ``subscriptions()`` gives the node's
    current subscriptions (its hot loop's), ``publishers()`` its current writers of
    :data:`WRITTEN_TOPICS`; answers are signed with ``guard``'s key. Call the loop's
    ``refresh()`` afterwards."""
    from std_srvs.srv import Trigger

    signer = guard.signer(service_name(node.get_name()))

    def answer(request: Any, response: Any) -> Any:
        subs = list(subscriptions())
        waiting = unmatched(subs)
        response.success = not waiting
        response.message = seal(signer, response.success,
                                ",".join(waiting) if waiting else counted(subs, publishers()))
        return response
    return node.create_service(Trigger, service_name(node.get_name()), answer)


__all__ = ["COUNTED_TOPICS", "SERVICE", "SIM_TOPICS", "WRITER", "WRITTEN_TOPICS", "behind",
           "counted", "offer", "opened", "seal", "service_name", "unmatched"]
