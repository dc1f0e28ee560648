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

#: Port health check of the graph's processes (ms): longer than their 5 s lease (see below).
HEALTHY_CHECK_MS = 10000
#: Port queue (messages) a graph process listens on ...
PORT_QUEUE = 4096
#: ... and the one of the processes that come and go while the loop runs (see below).
SHORT_PORT_QUEUE = 1024
#: The nodes that listen on a :data:`SHORT_PORT_QUEUE`.
SHORT_PORT_NODES = ("pd_p_controller", "pd_pf_controller")

#: Fast DDS profile of the graph's processes (used when discovery is localhost-only and no
#: profile is set): a larger shared-memory segment and port queue (the defaults, 0.5 MB and
#: 512 messages per process, fill up when one process stalls for ~0.1 s at 1 kHz, and the
#: lost samples then wait for the next heartbeat: up to 3 s, which stalled the loop for
#: 1.5 s in realtime runs), and writers that send heartbeats every 50 ms and answer NACKs at
#: once, so that a sample lost anyway is repaired within a few ticks. UDP stays on the
#: loopback interface. A participant's lease is 5 s (announced every 1 s; Fast DDS's
#: default is 20 s): a node that dies without saying goodbye (SIGKILL) is dropped by the
#: others within 5 s, so the graph stops sending it samples.
#:
#: Until then its readers stay matched, and every sample for them goes into its
#: shared-memory port, where nobody takes it. With Fast DDS's default port health check
#: (1 s) a sender's watchdog declared such a port dead about 1.5 s after the kill, and from
#: then on every sample sent to it re-created the port (open, mmap, munmap: ~28000 openat
#: calls in the sim within 3.5 s, its CPU time up by ~90 %; on time 80-83 % after the kill
#: against 95 % before, at 500 Hz). With a health check longer than the lease
#: (:data:`HEALTHY_CHECK_MS`) the port is never re-created; the dead port's queue fills up
#: instead, and every buffer it holds stays allocated in the sender's segment, which Fast
#: DDS walks on every allocation (its ``recover_buffers``): with a 4096-deep queue the sim's
#: CPU time stayed ~25 % up for the rest of the run. So the processes that are expected to
#: come and go while the loop runs (the controllers: switched, restarted, killed) listen on
#: a shorter queue (:data:`SHORT_PORT_QUEUE`; :func:`port_queue_for`), which bounds what a
#: dead one leaves allocated in its senders (measured: no rise in the sim's CPU time
#: outside the noise, docs/benchmarks.md). Shorter leases were tried and dropped: with
#: 1-2 s the dead controller cost 17-824 late ticks, but under a loaded lockstep run (a
#: recorder joining) a live node was twice dropped by a peer whose lease ran out before its
#: announcements were processed, and the peer never matched its endpoints again.
FASTDDS_PROFILE = f"""<?xml version="1.0" encoding="UTF-8" ?>
<dds xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <profiles>
    <transport_descriptors>
      <transport_descriptor>
        <transport_id>hexapod_shm</transport_id>
        <type>SHM</type>
        <segment_size>8388608</segment_size>
        <port_queue_capacity>{PORT_QUEUE}</port_queue_capacity>
        <healthy_check_timeout_ms>{HEALTHY_CHECK_MS}</healthy_check_timeout_ms>
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


def port_queue_for(node: str) -> int | None:
    """The port queue capacity node ``node`` listens on, if not the profile's default."""
    return SHORT_PORT_QUEUE if node in SHORT_PORT_NODES else None


#: Participant ids given to restarted processes (:func:`private_profile`): above the ids
#: Fast DDS hands out to a graph's own participants (0, 1, ... in start order), below 120
#: (the unicast ports of id 125 would be the next domain's).
RESTART_PARTICIPANT_IDS = range(60, 120)


def private_profile(directory: str | os.PathLike[str] | None = None,
                    remove_at_exit: bool = False, participant_id: int | None = None,
                    port_queue: int | None = None) -> Path:
    """Write :data:`FASTDDS_PROFILE` to ``directory`` (default: a new private temporary
    directory, mode 0700) as a file only its owner can read and write; its path.

    ``participant_id`` fixes the participant's id, hence its ports (default: the first one
    free). A process started in place of one that was SIGKILLed would otherwise take the
    dead one's id and open its shared-memory port as the dead process left it; a recorder
    restarted that way sometimes never received a sample (1 run of 8 of the recorder-kill
    test: its shared-memory receive thread never woke), so the launcher gives restarted
    processes ids of their own (:data:`RESTART_PARTICIPANT_IDS`).

    ``port_queue`` sets the capacity of the participant's shared-memory port (default:
    the profile's; :func:`port_queue_for`)."""
    made = directory is None
    folder = Path(tempfile.mkdtemp(prefix="hexapod_dds_") if made else directory)
    text, name = FASTDDS_PROFILE, "fastdds_profile.xml"
    if participant_id is not None:
        text = text.replace("      <rtps>\n", "      <rtps>\n        <participantID>"
                            f"{participant_id}</participantID>\n", 1)
        name = f"fastdds_profile_{participant_id}.xml"
    if port_queue is not None:
        text = text.replace(f"<port_queue_capacity>{PORT_QUEUE}<",
                            f"<port_queue_capacity>{port_queue}<", 1)
        name = name.replace(".xml", f"_q{port_queue}.xml")
    path = folder / name
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(text)
    if made and remove_at_exit:
        atexit.register(shutil.rmtree, folder, True)
    return path


__all__ = ["FASTDDS_PROFILE", "HEALTHY_CHECK_MS", "PORT_QUEUE", "RESTART_PARTICIPANT_IDS",
           "SHORT_PORT_NODES", "SHORT_PORT_QUEUE", "port_queue_for", "private_profile"]
