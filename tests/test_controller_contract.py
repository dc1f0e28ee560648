"""The controller contract's ROS-free parts (docs/controllers.md): the trailer written from
the doc's text with hashlib is the graph's, the signing helper, the naming rule."""
from __future__ import annotations

import hashlib
import secrets
import struct

import pytest

from hexapod_common import auth
from hexapod_common.core.controller_names import check_name, name_of, node_of, reserved_hint
from hexapod_common.core.errors import ParameterError
from hexapod_common.core.msg_auth import Rejected, Verifier, new_key_file, read_key_file

TOPIC = "/hexapod/joint_commands"


def doc_sign(key: bytes, topic: str, payload: bytes, sender: bytes, seq: int) -> bytes:
    """docs/controllers.md, "The trailer, exactly", line by line."""
    pad = -len(payload) % 8
    body = payload + b"\0" * pad
    head = sender + struct.pack("<Q", seq | pad << 56)
    tag = hashlib.blake2b(topic.encode() + b"\0" + body + head, key=key, digest_size=16)
    return body + head + tag.digest()


@pytest.mark.parametrize("size", [4, 13, 16, 311])
def test_the_docs_trailer_is_accepted_by_the_graphs_verifier(size):
    key = secrets.token_bytes(32)
    payload = b"\x00\x01\x00\x00" + secrets.token_bytes(size - 4)
    sender = secrets.token_bytes(8)
    v = Verifier(key, TOPIC)
    data = doc_sign(key, TOPIC, payload, sender, 1)
    assert len(data) % 8 == 0 and len(data) - len(payload) - (-size % 8) == 32
    assert v.verify(data) == payload
    with pytest.raises(Rejected, match="replayed"):
        v.verify(data)
    assert v.verify(doc_sign(key, TOPIC, payload, sender, 2)) == payload
    for bad in (doc_sign(key, "/hexapod/reference", payload, sender, 3),  # other topic
                doc_sign(secrets.token_bytes(32), TOPIC, payload, sender, 4),  # other key
                payload):  # no trailer
        with pytest.raises(Rejected, match="unauthenticated"):
            v.verify(bad)


def test_the_helper_signs_with_the_key_file_and_is_off_with_auth_off(tmp_path):
    path = new_key_file(tmp_path)
    key = read_key_file(path)
    sign = auth.signer(TOPIC, {"HEXAPOD_KEY_FILE": str(path)})
    payload = b"\x00\x01\x00\x00abcde"
    assert Verifier(key, TOPIC).verify(sign.sign(payload)) == payload
    assert sign.enabled
    off = auth.signer(TOPIC, {"HEXAPOD_AUTH": "off"})
    assert off.sign(payload) == payload and not off.enabled
    with pytest.raises(auth.AuthError, match="no run key: set HEXAPOD_KEY_FILE"):
        auth.signer(TOPIC, {})


def test_naming_rule_is_one_to_one():
    assert node_of("pd_p") == "pd_p_controller" and name_of("pd_p_controller") == "pd_p"
    assert node_of("my_controller") == "my_controller"
    assert name_of("my_controller") == "my_controller"
    assert name_of("x_controller") == "x_controller"
    # a node named as a built-in controller serves none (its node is pd_p_controller)
    assert name_of("pd_p") is None and node_of("pd_p") != "pd_p"
    assert "served by the node pd_p_controller" in reserved_hint("pd_p")
    assert reserved_hint("pd_p_controller") == reserved_hint("my_controller") == ""
    for node in ("pd_p_controller", "pd_pf_controller", "my_controller", "x_controller"):
        assert node_of(name_of(node)) == node
    for bad in ("", "pd/x", "1abc", "a-b", "a" * 65, 3):
        with pytest.raises(ParameterError, match="a controller name"):
            check_name(bad)
