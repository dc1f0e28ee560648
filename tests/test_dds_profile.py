"""The graph's Fast DDS profile (hexapod_sim/runtime/dds_profile.py): private, well-formed,
and with a fixed participant id for restarted processes."""
from __future__ import annotations

import stat
import xml.etree.ElementTree as ET

import pytest

from hexapod_sim.runtime.dds_profile import (HEALTHY_CHECK_MS, PORT_QUEUE,
                                             RESTART_PARTICIPANT_IDS, SHORT_PORT_NODES,
                                             SHORT_PORT_QUEUE, port_queue_for,
                                             private_profile)

NS = {"d": "http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles"}


def _rtps(path):
    root = ET.parse(path).getroot()
    return root.find("d:profiles/d:participant/d:rtps", NS)


def test_the_profile_is_private_and_lets_fast_dds_choose_the_participant_id(tmp_path):
    path = private_profile(tmp_path)
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    assert _rtps(path).find("d:participantID", NS) is None
    with pytest.raises(FileExistsError):  # never written over (nor through a planted file)
        private_profile(tmp_path)


def test_a_restarted_process_gets_a_participant_id_of_its_own(tmp_path):
    first = private_profile(tmp_path)
    ids = [RESTART_PARTICIPANT_IDS[0], RESTART_PARTICIPANT_IDS[1]]
    paths = [private_profile(tmp_path, participant_id=i) for i in ids]
    assert len({first, *paths}) == 3
    for path, i in zip(paths, ids):
        assert _rtps(path).find("d:participantID", NS).text == str(i)
        # everything else is the same profile
        assert ET.tostring(_rtps(path).find("d:builtin", NS)) == ET.tostring(
            _rtps(first).find("d:builtin", NS))
    # ids whose unicast ports stay inside the domain's range (7400 + 250 d + 10 + 2 id + 1)
    assert RESTART_PARTICIPANT_IDS[-1] < 125


def _shm(path):
    root = ET.parse(path).getroot()
    for d in root.findall("d:profiles/d:transport_descriptors/d:transport_descriptor", NS):
        if d.find("d:type", NS).text == "SHM":
            return d
    raise AssertionError("no SHM transport")


def test_a_dead_readers_port_is_never_recreated_while_its_lease_runs(tmp_path):
    # A port health check shorter than the lease made every sample for a SIGKILLed
    # controller re-create its port until the lease ran out (dds_profile.py).
    path = private_profile(tmp_path)
    lease = _rtps(path).find("d:builtin/d:discovery_config/d:leaseDuration/d:sec", NS)
    check_ms = int(_shm(path).find("d:healthy_check_timeout_ms", NS).text)
    assert check_ms == HEALTHY_CHECK_MS > int(lease.text) * 1000


def test_the_controllers_listen_on_a_short_port_queue(tmp_path):
    assert {port_queue_for(n) for n in SHORT_PORT_NODES} == {SHORT_PORT_QUEUE}
    assert SHORT_PORT_NODES == ("pd_p_controller", "pd_pf_controller")
    for node in ("hexapod_sim", "metrics", "trajectory_generator", ""):
        assert port_queue_for(node) is None
    default = private_profile(tmp_path)
    short = private_profile(tmp_path, port_queue=SHORT_PORT_QUEUE)
    both = private_profile(tmp_path, participant_id=RESTART_PARTICIPANT_IDS[0],
                           port_queue=SHORT_PORT_QUEUE)
    assert len({default, short, both}) == 3
    assert int(_shm(default).find("d:port_queue_capacity", NS).text) == PORT_QUEUE
    for path in (short, both):
        assert int(_shm(path).find("d:port_queue_capacity", NS).text) == SHORT_PORT_QUEUE
        # nothing else of the transport changes
        assert ET.tostring(_shm(path).find("d:healthy_check_timeout_ms", NS)) == ET.tostring(
            _shm(default).find("d:healthy_check_timeout_ms", NS))
    assert _rtps(both).find("d:participantID", NS).text == str(RESTART_PARTICIPANT_IDS[0])
