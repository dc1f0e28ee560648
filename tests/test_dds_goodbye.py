"""The goodbye the launcher says for a node killed by a signal (dds_goodbye.py).

The end-to-end check (a SIGKILLed controller leaves the others' view within a second, its
lease being 5 s) is tests/graph/test_graph_exits.py; here: the RTPS message, the log line
it is built from, and the datagrams on a real socket."""
from __future__ import annotations

import socket
import struct

import pytest

from hexapod_common.runtime.dds_goodbye import (PREFIX_LOG, GoodbyeError, goodbye_datagram,
                                                metatraffic_ports, prefix_from_log, send_goodbye)
from hexapod_common.runtime.dds_profile import DOMAIN_PARTICIPANT_IDS, unicast_ports

PREFIX = bytes.fromhex("010f78fd3a7fbecd07000000")


def test_the_goodbye_is_one_rtps_data_submessage_disposing_the_participant():
    msg = goodbye_datagram(PREFIX)
    assert msg[:4] == b"RTPS" and msg[4:6] == bytes([2, 3]) and msg[8:20] == PREFIX
    sub = msg[20:]
    assert sub[0] == 0x15 and sub[1] == 0x03  # DATA, little endian, inline QoS, no payload
    (length,) = struct.unpack("<H", sub[2:4])
    assert length == len(sub) - 4
    body = sub[4:]
    assert body[4:8] == bytes.fromhex("000100c7") and body[8:12] == bytes.fromhex("000100c2")
    qos = body[20:]
    params = {}
    while qos:
        pid, plen = struct.unpack("<HH", qos[:4])
        params[pid] = qos[4:4 + plen]
        qos = qos[4 + plen:]
        if pid == 1:
            break
    assert not qos  # the sentinel ends the message
    assert params[0x0070] == PREFIX + bytes.fromhex("000001c1")  # key hash: its GUID
    assert params[0x0071] == bytes([0, 0, 0, 3])  # disposed | unregistered


@pytest.mark.parametrize("bad", [b"", PREFIX[:11], PREFIX + b"\0"])
def test_a_prefix_that_is_not_12_bytes_is_refused(bad):
    with pytest.raises(GoodbyeError, match="12 bytes"):
        goodbye_datagram(bad)


def test_the_launcher_reads_the_latest_prefix_a_node_logged():
    log = (f"[INFO] [1.0] [pd_p_controller]: {PREFIX_LOG} {'ab' * 12}\n"
           "[INFO] [2.0] [pd_p_controller]: configured\n"
           f"[INFO] [3.0] [pd_p_controller]: {PREFIX_LOG} {PREFIX.hex()}\n")  # restarted
    assert prefix_from_log(log) == PREFIX
    assert prefix_from_log("[INFO] [1.0] [sim]: nothing here\n") is None
    assert prefix_from_log(f"{PREFIX_LOG} 010f\n") is None  # cut short


def test_the_goodbye_reaches_every_participant_port_of_the_domain():
    ports = metatraffic_ports(42)
    assert ports == [unicast_ports(42, i)[0] for i in DOMAIN_PARTICIPANT_IDS]
    free = [p for p in ports if _bindable(p)]
    if not free:
        pytest.skip("every discovery port of domain 42 is taken here")
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as listener:
        listener.bind(("127.0.0.1", free[-1]))
        listener.settimeout(5)
        assert send_goodbye(PREFIX, 42) == len(ports)
        assert listener.recv(4096) == goodbye_datagram(PREFIX)


def _bindable(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True

