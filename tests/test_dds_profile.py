"""The graph's Fast DDS profile (hexapod_sim/runtime/dds_profile.py): private, well-formed,
and with a fixed participant id for restarted processes."""
from __future__ import annotations

import stat
import xml.etree.ElementTree as ET

import pytest

from hexapod_sim.runtime.dds_profile import (HEALTHY_CHECK_MS, PORT_QUEUE, READER_MAX_SAMPLES,
                                             RESTART_PARTICIPANT_IDS, private_profile)

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


def test_the_shared_memory_transport_is_sized_and_checked_as_documented(tmp_path):
    # dds_profile.py: the port queue bounds what a SIGKILLed reader leaves allocated in its
    # senders; the port check (longer than Fast DDS's 1 s, shorter than the 5 s lease and
    # than the 5 s `hexapod status` waits for the graph) shortens the port re-creation
    # after such a kill without keeping new processes from discovering the graph.
    path = private_profile(tmp_path)
    lease = _rtps(path).find("d:builtin/d:discovery_config/d:leaseDuration/d:sec", NS)
    assert int(_shm(path).find("d:port_queue_capacity", NS).text) == PORT_QUEUE == 1024
    check = int(_shm(path).find("d:healthy_check_timeout_ms", NS).text)
    assert check == HEALTHY_CHECK_MS and 1000 < check < int(lease.text) * 1000


def test_a_reader_may_hold_as_many_untaken_samples_as_its_depth(tmp_path):
    from hexapod_sim.core.topics import CONTROL_DEPTH, HISTORY_DEPTH, RECORD_DEPTH

    limits = ET.parse(private_profile(tmp_path)).getroot().find(
        "d:profiles/d:data_reader/d:topic/d:resourceLimitsQos", NS)
    assert int(limits.find("d:max_samples", NS).text) == READER_MAX_SAMPLES
    assert int(limits.find("d:max_samples_per_instance", NS).text) == READER_MAX_SAMPLES
    assert READER_MAX_SAMPLES >= max(RECORD_DEPTH, HISTORY_DEPTH, CONTROL_DEPTH)
