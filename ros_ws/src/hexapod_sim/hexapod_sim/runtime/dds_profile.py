"""The Fast DDS profile of the graph's processes, written privately (no ROS imports).

The profile keeps UDP on the loopback interface and sizes the shared-memory transport
(:data:`FASTDDS_PROFILE`). It is never read from a shared, predictable path (a file planted
there by another user could open the ports on every interface): :func:`private_profile`
writes it into a fresh directory of its own (``mkdtemp``: mode 0700, owner only), per run
(the launcher) or per node process started by hand.
"""
from __future__ import annotations

import atexit
import os
import shutil
import tempfile
from pathlib import Path

#: Fast DDS profile of the graph's processes (used when discovery is localhost-only and no
#: profile is set): a larger shared-memory segment and port queue (the defaults, 0.5 MB and
#: 512 messages per process, fill up when one process stalls for ~0.1 s at 1 kHz, and the
#: lost samples then wait for the next heartbeat: up to 3 s, which stalled the loop for
#: 1.5 s in realtime runs), and writers that send heartbeats every 50 ms and answer NACKs at
#: once, so that a sample lost anyway is repaired within a few ticks. UDP stays on the
#: loopback interface. A participant's lease is 5 s (announced every 1 s; Fast DDS's
#: default is 20 s): a node that dies without saying goodbye (SIGKILL) is dropped by the
#: others within 5 s, so the graph stops sending it samples. Until then the loop is
#: disturbed: with a SIGKILLed idle controller 80-97 % of realtime 1 kHz ticks were on time
#: against 89-99 % without (docs/benchmarks.md): every sample sent to the dead process's
#: shared-memory port (marked not OK by Fast DDS's watchdog) reopens the port (open, mmap,
#: munmap: ~10 % of the sim's main thread in a profile). Best-effort readers for the
#: controllers, a 50 ms port health check and UDP only did not help. Shorter leases were tried and
#: dropped: with 1-2 s the dead controller cost 17-824 late ticks, but under a loaded
#: lockstep run (a recorder joining) a live node was twice dropped by a peer whose lease ran
#: out before its announcements were processed, and the peer never matched its endpoints
#: again (a controller waited for references for the rest of the run; possibly the
#: shared-memory port reuse that :func:`private_profile` now avoids for restarts, which was
#: not known then).
FASTDDS_PROFILE = """<?xml version="1.0" encoding="UTF-8" ?>
<dds xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <profiles>
    <transport_descriptors>
      <transport_descriptor>
        <transport_id>hexapod_shm</transport_id>
        <type>SHM</type>
        <segment_size>8388608</segment_size>
        <port_queue_capacity>4096</port_queue_capacity>
      </transport_descriptor>
      <transport_descriptor>
        <transport_id>hexapod_udp</transport_id>
        <type>UDPv4</type>
        <interfaceWhiteList><address>127.0.0.1</address></interfaceWhiteList>
      </transport_descriptor>
    </transport_descriptors>
    <participant profile_name="hexapod_participant" is_default_profile="true">
      <rtps>
        <userTransports>
          <transport_id>hexapod_shm</transport_id>
          <transport_id>hexapod_udp</transport_id>
        </userTransports>
        <useBuiltinTransports>false</useBuiltinTransports>
        <builtin>
          <discovery_config>
            <leaseDuration><sec>5</sec><nanosec>0</nanosec></leaseDuration>
            <leaseAnnouncement><sec>1</sec><nanosec>0</nanosec></leaseAnnouncement>
          </discovery_config>
        </builtin>
      </rtps>
    </participant>
    <data_writer profile_name="hexapod_writer" is_default_profile="true">
      <times>
        <heartbeatPeriod><sec>0</sec><nanosec>50000000</nanosec></heartbeatPeriod>
        <nackResponseDelay><sec>0</sec><nanosec>0</nanosec></nackResponseDelay>
      </times>
    </data_writer>
    <data_reader profile_name="hexapod_reader" is_default_profile="true">
      <times>
        <heartbeatResponseDelay><sec>0</sec><nanosec>0</nanosec></heartbeatResponseDelay>
      </times>
    </data_reader>
  </profiles>
</dds>
"""


#: Participant ids given to restarted processes (:func:`private_profile`): above the ids
#: Fast DDS hands out to a graph's own participants (0, 1, ... in start order), below 120
#: (the unicast ports of id 125 would be the next domain's).
RESTART_PARTICIPANT_IDS = range(60, 120)


def private_profile(directory: str | os.PathLike[str] | None = None,
                    remove_at_exit: bool = False, participant_id: int | None = None) -> Path:
    """Write :data:`FASTDDS_PROFILE` to ``directory`` (default: a new private temporary
    directory, mode 0700) as a file only its owner can read and write; its path.

    ``participant_id`` fixes the participant's id, hence its ports (default: the first one
    free). A process started in place of one that was SIGKILLed would otherwise take the
    dead one's id and open its shared-memory port as the dead process left it; a recorder
    restarted that way sometimes never received a sample (1 run of 8 of the recorder-kill
    test: its shared-memory receive thread never woke), so the launcher gives restarted
    processes ids of their own (:data:`RESTART_PARTICIPANT_IDS`)."""
    made = directory is None
    folder = Path(tempfile.mkdtemp(prefix="hexapod_dds_") if made else directory)
    text, name = FASTDDS_PROFILE, "fastdds_profile.xml"
    if participant_id is not None:
        text = text.replace("      <rtps>\n", "      <rtps>\n        <participantID>"
                            f"{participant_id}</participantID>\n", 1)
        name = f"fastdds_profile_{participant_id}.xml"
    path = folder / name
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(text)
    if made and remove_at_exit:
        atexit.register(shutil.rmtree, folder, True)
    return path


__all__ = ["FASTDDS_PROFILE", "RESTART_PARTICIPANT_IDS", "private_profile"]
