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
#: against 89-99 % without (docs/benchmarks.md). Why is not established: best-effort
#: readers for the controllers (no reliable writer keeping samples for the dead one) and a
#: 50 ms shared-memory port health check did not change it. Shorter leases were tried and
#: dropped: with 1-2 s the dead controller cost 17-824 late ticks, but under a loaded lockstep run (a recorder joining) a live node was twice dropped
#: by a peer whose lease ran out before its announcements were processed, and the peer never
#: matched its endpoints again (a controller waited for references for the rest of the run).
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


def private_profile(directory: str | os.PathLike[str] | None = None,
                    remove_at_exit: bool = False) -> Path:
    """Write :data:`FASTDDS_PROFILE` to ``directory`` (default: a new private temporary
    directory, mode 0700) as a file only its owner can read and write; its path."""
    made = directory is None
    folder = Path(tempfile.mkdtemp(prefix="hexapod_dds_") if made else directory)
    path = folder / "fastdds_profile.xml"
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(FASTDDS_PROFILE)
    if made and remove_at_exit:
        atexit.register(shutil.rmtree, folder, True)
    return path


__all__ = ["FASTDDS_PROFILE", "private_profile"]
