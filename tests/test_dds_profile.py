"""The graph's Fast DDS profile (hexapod_sim/runtime/dds_profile.py): private, well-formed,
and with a fixed participant id for restarted processes."""
from __future__ import annotations

import stat
import xml.etree.ElementTree as ET

import pytest

from hexapod_sim.runtime.dds_profile import RESTART_PARTICIPANT_IDS, private_profile

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
