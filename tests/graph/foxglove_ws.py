"""A minimal Foxglove WebSocket protocol client (subprotocol ``foxglove.sdk.v1``) for the tests.

Enough of the protocol to check a live server: read ``serverInfo`` and ``advertise``,
subscribe to one channel by topic, collect its ``MessageData`` frames (opcode 1:
subscription id u32, log time u64, payload).
"""
from __future__ import annotations

import json
import struct
import time
from typing import Any

from websockets.sync.client import connect

SUBPROTOCOL = "foxglove.sdk.v1"
_DATA = struct.Struct("<BIQ")


def collect(url: str, topic: str, count: int, timeout: float = 60.0
            ) -> tuple[dict[str, Any], dict[str, Any], list[tuple[int, bytes]]]:
    """(serverInfo, the topic's advertised channel, ``count`` (log time ns, payload))."""
    end = time.monotonic() + timeout
    out: list[tuple[int, bytes]] = []
    info: dict[str, Any] = {}
    channel: dict[str, Any] | None = None
    with connect(url, subprotocols=[SUBPROTOCOL], open_timeout=timeout,
                 max_size=None) as ws:
        while len(out) < count:
            left = end - time.monotonic()
            if left <= 0:
                raise TimeoutError(f"{len(out)} of {count} messages of {topic} in {timeout:g} s"
                                   f" (channel {'seen' if channel else 'not advertised'})")
            frame = ws.recv(timeout=left)
            if isinstance(frame, str):
                msg = json.loads(frame)
                if msg.get("op") == "serverInfo":
                    info = msg
                elif msg.get("op") == "advertise" and channel is None:
                    for ch in msg["channels"]:
                        if ch["topic"] == topic:
                            channel = ch
                            ws.send(json.dumps({"op": "subscribe", "subscriptions": [
                                {"id": 1, "channelId": ch["id"]}]}))
                continue
            if frame[0] != 1:  # 2 = Time (the server's clock), others we do not ask for
                continue
            opcode, sub, log_time = _DATA.unpack_from(frame)
            if sub == 1:
                out.append((log_time, bytes(frame[_DATA.size:])))
    assert channel is not None
    return info, channel, out
