"""Sign your own node's messages for a hexapod graph (the public helper).

Every message on a contract topic ends with a 32-byte trailer that proves it comes from a
process holding the run's key (docs/controllers.md, "Authentication", gives the exact
layout so it can be written in any language). From Python::

    from hexapod_common.auth import signer

    sign = signer("/hexapod/joint_commands")        # finds the key via HEXAPOD_KEY_FILE
    publisher.publish(sign.message(msg))            # msg: a sensor_msgs/JointState

:func:`signer` reads the key file named by ``HEXAPOD_KEY_FILE`` (``scripts/run_graph.sh``
prints the path) and raises :class:`AuthError` with one line if there is none; with
``HEXAPOD_AUTH=off`` it returns a signer that adds nothing. One signer per publisher: it
holds the publisher's random sender id and its sequence numbers.
"""
from __future__ import annotations

import os
from typing import Any, Mapping

from .core.msg_auth import (AUTH_ENV, KEY_ENV, TRAILER_BYTES, AuthError, Signer, Unsigned,
                            run_key)


class TopicSigner:
    """Signs the messages of one publisher on ``topic`` (see the module docstring)."""

    def __init__(self, topic: str, env: Mapping[str, str] | None = None) -> None:
        key = run_key(os.environ if env is None else env)
        self.topic = topic
        self.enabled = key is not None
        self._signer: Signer | Unsigned = Unsigned(topic) if key is None else Signer(key, topic)

    def sign(self, payload: bytes) -> bytes:
        """A serialized (CDR) message with its trailer appended."""
        return self._signer.sign(bytes(payload))

    def message(self, msg: Any) -> bytes:
        """A ROS message serialized and signed: publish the bytes with an rclpy publisher
        (``publisher.publish(data)`` accepts serialized messages)."""
        from rclpy.serialization import serialize_message

        return self.sign(serialize_message(msg))


def signer(topic: str, env: Mapping[str, str] | None = None) -> TopicSigner:
    """A :class:`TopicSigner` for one publisher on ``topic``, keyed from the environment."""
    return TopicSigner(topic, env)


__all__ = ["AUTH_ENV", "AuthError", "KEY_ENV", "TRAILER_BYTES", "TopicSigner", "signer"]
