"""A dead node's DDS goodbye, said for it by the launcher (no ROS imports).

A node that exits sends its participant's goodbye (an SPDP ``DATA(p[UD])``: the participant
disposed and unregistered), and its peers drop its readers at once. A node killed by a
signal says nothing: its peers keep it, and keep writing samples into its shared-memory
port, until its lease runs out (5 s, ``dds_profile.py``), and those writes cost the
simulator's loop ticks. The launcher knows at once that the process died, so it sends the
goodbye on the dead participant's behalf (:func:`send_goodbye`) to every participant of the
domain on this host; they drop the dead one within a few milliseconds, as after a clean
exit.

It needs the dead participant's GUID prefix (12 bytes; Fast DDS fills 2 of them at random,
so it cannot be derived from the pid): every node logs it at start
(:func:`participant_prefix`, :data:`PREFIX_LOG`) and the launcher reads it from the node's
log (:func:`prefix_from_log`).

What this does not reach: participants on other hosts (the graph's discovery is
localhost-only), and nodes started by hand (nobody watches them). Any process on the domain
can send such a message for any participant: without DDS security (not in the wheels),
discovery is not authenticated, and this module adds no new power to anyone.
"""
from __future__ import annotations

import re
import socket
import struct
from collections.abc import Iterable
from typing import Any

from .dds_profile import DOMAIN_PARTICIPANT_IDS, unicast_ports

#: What every node logs once at start, with its participant's GUID prefix in hex.
PREFIX_LOG = "DDS participant"
_PREFIX_RE = re.compile(PREFIX_LOG + r" ([0-9a-f]{24})\b")

_ENTITY_SPDP_WRITER = bytes.fromhex("000100c2")
_ENTITY_SPDP_READER = bytes.fromhex("000100c7")
_ENTITY_PARTICIPANT = bytes.fromhex("000001c1")
_PID_SENTINEL, _PID_KEY_HASH, _PID_STATUS_INFO = 0x0001, 0x0070, 0x0071
_STATUS_DISPOSED_UNREGISTERED = bytes([0, 0, 0, 3])
_SUBMSG_DATA, _FLAG_LITTLE_ENDIAN, _FLAG_INLINE_QOS = 0x15, 0x01, 0x02
#: RTPS 2.3, vendor eProsima (what the graph's own participants send).
_HEADER = b"RTPS" + bytes([2, 3, 1, 15])
#: The goodbye's sequence number: above any the dead participant's announcer reached.
_SEQUENCE = 0x7FFFFFFF


class GoodbyeError(ValueError):
    """A GUID prefix that is not 12 bytes."""


def participant_prefix(node: Any) -> bytes | None:
    """The GUID prefix (12 bytes) of ``node``'s DDS participant, from the graph's view of
    the node's own ``/rosout`` publisher (``endpoint_gid``: prefix + entity id); None when
    the node has no such publisher (rosout disabled) or the middleware gives no GUID."""
    name, ns = node.get_name(), node.get_namespace()
    for info in node.get_publishers_info_by_topic("/rosout"):
        if info.node_name == name and info.node_namespace == ns:
            gid = bytes(info.endpoint_gid)
            if len(gid) >= 16 and gid[:2] == bytes([1, 15]):
                return gid[:12]
    return None


def prefix_from_log(text: str) -> bytes | None:
    """The last participant GUID prefix a node logged (:data:`PREFIX_LOG`), None if none."""
    found = _PREFIX_RE.findall(text)
    return bytes.fromhex(found[-1]) if found else None


def goodbye_datagram(prefix: bytes) -> bytes:
    """The RTPS message by which the participant ``prefix`` says goodbye: one DATA
    submessage from its SPDP writer, inline QoS key hash = its GUID, status info disposed
    and unregistered, no payload (what Fast DDS sends when a participant is deleted)."""
    if len(prefix) != 12:
        raise GoodbyeError(f"a GUID prefix is 12 bytes, got {len(prefix)}")
    inline_qos = (struct.pack("<HH", _PID_KEY_HASH, 16) + prefix + _ENTITY_PARTICIPANT
                  + struct.pack("<HH", _PID_STATUS_INFO, 4) + _STATUS_DISPOSED_UNREGISTERED
                  + struct.pack("<HH", _PID_SENTINEL, 0))
    body = (struct.pack("<HH", 0, 16)  # extra flags; octets from here to the inline QoS
            + _ENTITY_SPDP_READER + _ENTITY_SPDP_WRITER
            + struct.pack("<iI", 0, _SEQUENCE) + inline_qos)
    submessage = (bytes([_SUBMSG_DATA, _FLAG_LITTLE_ENDIAN | _FLAG_INLINE_QOS])
                  + struct.pack("<H", len(body)) + body)
    return _HEADER + prefix + submessage


def metatraffic_ports(domain_id: int,
                      ids: Iterable[int] = DOMAIN_PARTICIPANT_IDS) -> list[int]:
    """The metatraffic (discovery) unicast UDP ports of participants ``ids`` of
    ``domain_id`` (:func:`~.dds_profile.unicast_ports`)."""
    return [unicast_ports(domain_id, i)[0] for i in ids]


def send_goodbye(prefix: bytes, domain_id: int, host: str = "127.0.0.1") -> int:
    """Send participant ``prefix``'s goodbye to every participant id of ``domain_id`` on
    ``host`` (a datagram to a port nobody holds is lost, harmlessly); the datagrams sent."""
    message = goodbye_datagram(prefix)
    sent = 0
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        for port in metatraffic_ports(domain_id):
            try:
                sock.sendto(message, (host, port))
                sent += 1
            except OSError:
                continue
    return sent


__all__ = ["GoodbyeError", "PREFIX_LOG", "goodbye_datagram",
           "metatraffic_ports", "participant_prefix", "prefix_from_log", "send_goodbye"]
