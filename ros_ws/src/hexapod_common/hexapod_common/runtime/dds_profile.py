"""The Fast DDS profile of the graph's processes, written privately (no ROS imports).

The profile keeps UDP on the loopback interface and sizes the shared-memory transport
(:data:`FASTDDS_PROFILE`). It is never read from a shared, predictable path (a file planted
there by another user could open the ports on every interface): :func:`private_profile`
writes it into a fresh directory of its own (``mkdtemp``: mode 0700, owner only), per run
(the launcher) or per node process started by hand.
"""
from __future__ import annotations

import atexit
import contextlib
import fcntl
import hashlib
import os
import re
import shutil
import tempfile
import time
from pathlib import Path
from typing import IO, Iterable, Mapping

from hexapod_common.core.topic_names import CLOCK, RECORDED, TICK_TOPICS

#: Port queue (messages) of every graph process's shared-memory port (see below).
PORT_QUEUE = 1024
#: How long (ms) a sender waits for the listeners of a shared-memory port to show they are
#: alive before declaring the port broken (Fast DDS's default: 1000). Longer than the
#: participants' lease (:data:`LEASE_S`), so that a node killed without a goodbye is dropped
#: by its peers before any of them declares its port broken (see below), and longer than a
#: stop of a live process that lockstep waits out (a port whose listener was stopped for 3 s
#: must not be declared broken). 10 s (with a 5 s lease, announced every 1 s) made the test
#: suite fail in 3 of 7 runs; 6 s with 0.25 s announcements is what the suite runs.
HEALTHY_CHECK_MS = 6000
#: A participant's lease (s) and how often it announces itself (s): see
#: :data:`FASTDDS_PROFILE`. Longer than a process may be stopped (``kill -STOP``) or starved
#: and still be waited for: lockstep waits for the living (sim_node, runtime/liveness.py),
#: and a participant dropped by its peers loses what was sent to it meanwhile (a 2 s lease
#: lost the recorder's samples of a 3 s stop). The launcher's nodes are known dead at once
#: by their pid; a joined node that dies is dropped after this lease.
LEASE_S = 5
ANNOUNCE_S = 0.25

#: Most samples a reader of the graph holds untaken. Fast DDS's default (5000) applies
#: whatever the subscription's depth: a recorder that took nothing for a while (its main
#: thread yields to the real-time control path) kept the first 5000 samples of a topic and
#: lost every later one without a word (``RECORD_DEPTH`` is 10000; a realtime 1 kHz run of
#: 10 s recorded 5000-5657 of its 10201 joint states, and the bags were reported complete).
#: Above the graph's deepest queue (checked by tests/test_dds_profile.py).
READER_MAX_SAMPLES = 20000

#: Fast DDS profile of the graph's processes (used when discovery is localhost-only and no
#: profile is set): a larger shared-memory segment and port queue (the defaults, 0.5 MB and
#: 512 messages per process, filled up when one process stalled for ~0.1 s at 1 kHz, and
#: the lost samples then waited for the next heartbeat: up to 3 s, which stalled the loop
#: for 1.5 s in realtime runs), and writers that send heartbeats every 50 ms and answer
#: NACKs at once, so that a sample lost anyway is repaired within a few ticks. UDP stays on
#: the loopback interface.
#:
#: A node killed without a goodbye (SIGKILL, a crash): its peers keep it until its
#: participant's lease ends, and until then every sample for its readers goes into its
#: shared-memory port, where nobody takes it. Once a sender's watchdog has declared that port
#: broken (no sign of its listener for :data:`HEALTHY_CHECK_MS`), every sample sent to it
#: re-creates the port (open, mmap, munmap): with the earlier 5 s lease (announced every 1 s)
#: that cost the sim ~60 % of a core instead of ~44 % and 1-1.5 s of a realtime 1 kHz run at
#: 55-80 % of ticks on time, from ~3.5 s after an idle controller's SIGKILL until its lease
#: ended at ~4.6-4.8 s (``scripts/bench_switch.py --kill-idle 3``, two runs). So the lease
#: is shorter than the health check (:data:`LEASE_S` = 5 s, :data:`HEALTHY_CHECK_MS` = 6 s;
#: before lockstep waited for stopped processes, 2 s and 3 s): the dead participant is
#: dropped before any watchdog fires (with 2 s and 3 s no interval of those runs fell below
#: 95 % on time, side by side with the 5 s lease and its 3 s check). It is announced every
#: :data:`ANNOUNCE_S` = 0.25 s, 8 times per lease: an earlier try of 1-2 s leases announced
#: every 1 s (2 announcements per lease) made a loaded peer drop a live node twice. The
#: more frequent announcements (one small datagram per peer every 0.25 s) showed no cost in
#: those runs: the runs without a kill made 99.2-99.8 % on time after the kill tick with
#: either lease, the sim at 41-45 % of a core.
#: Meanwhile the dead port's queue fills up and each buffer it holds stays allocated in the
#: sender's shared-memory segment, which Fast DDS walks at every allocation (its
#: ``recover_buffers``): the reason for a 1024-deep queue rather than 4096.
#:
#: A process that takes the dead one's participant id opens its port as the dead process
#: left it. Restarted nodes and the graph's tools take ids whose ports do not exist
#: (:func:`unused_participant_id`); any other process (``ros2 node list``, an rclpy
#: script) picks the first id whose ports' listener locks are free, which after a SIGKILL
#: is often the dead one's (with a 10 s check it then heard nothing for 20 s and more). The
#: launcher therefore holds the locks of the ports of every node of its that died by a
#: signal (:class:`PortFence`), and deletes those ports once the graph is stopped; such a
#: process skips the id (Fast DDS prints one ``Failed init_port ... open_and_lock_file
#: failed`` line for it).
_WRITER_BODY = """\
      <times>
        <heartbeatPeriod><sec>0</sec><nanosec>50000000</nanosec></heartbeatPeriod>
        <nackResponseDelay><sec>0</sec><nanosec>0</nanosec></nackResponseDelay>
      </times>
"""
_READER_BODY = f"""\
      <topic>
        <resourceLimitsQos>
          <max_samples>{READER_MAX_SAMPLES}</max_samples>
          <max_samples_per_instance>{READER_MAX_SAMPLES}</max_samples_per_instance>
        </resourceLimitsQos>
      </topic>
      <times>
        <heartbeatResponseDelay><sec>0</sec><nanosec>0</nanosec></heartbeatResponseDelay>
      </times>
"""
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
            <leaseDuration><sec>{LEASE_S}</sec><nanosec>0</nanosec></leaseDuration>
            <leaseAnnouncement><sec>{int(ANNOUNCE_S)}</sec>\
<nanosec>{round(ANNOUNCE_S % 1 * 1e9)}</nanosec></leaseAnnouncement>
          </discovery_config>
        </builtin>
      </rtps>
    </participant>
    <data_writer profile_name="hexapod_writer" is_default_profile="true">
{_WRITER_BODY}    </data_writer>
    <data_reader profile_name="hexapod_reader" is_default_profile="true">
{_READER_BODY}    </data_reader>
<!--endpoints-->  </profiles>
</dds>
"""


#: The graph's per-tick topics but /clock, and the recorder's progress: a run keeps them in a
#: DDS partition of its own (:func:`partition_of`): a process on the domain that does not load
#: the run's profile (or derive its partition from the run's key) neither reads them nor
#: reaches the graph's readers with what it publishes on them, so a flood of copies wakes
#: no node of the graph (it used to cost each reader a wake-up, a take and a refusal in
#: Python per copy: docs/benchmarks.md, S7). Everything else (status, indices, the
#: controller in charge, parameters, services) stays in the default partition, where the
#: ros2 command line sees it; so does /clock, which tools run with sim time read (no node of
#: the graph subscribes to it unless started with --sim-time, and none acts on it). What an
#: attacker who reads the discovery traffic can still do: learn the partition's name (it is
#: announced in plain text with every endpoint) and publish into it; those messages then
#: reach the readers and are refused in Python by their signature (msg_auth.py), as before.
PARTITIONED_TOPICS = tuple(t for t in TICK_TOPICS if t != CLOCK) + (RECORDED,)


def partition_of(key: bytes) -> str:
    """The DDS partition of a run: a name derived from its key (so every process that holds
    the key file finds it, and nobody else can guess it)."""
    return "hexapod_" + hashlib.blake2b(key, digest_size=8, person=b"hexapod-part").hexdigest()


def run_partition(env: Mapping[str, str] = os.environ) -> str | None:
    """The partition of the run whose key ``env`` names (``HEXAPOD_KEY_FILE``); None with
    ``HEXAPOD_AUTH=off`` or no key file named (msg_auth.AuthError if it is unreadable)."""
    from hexapod_common.core.msg_auth import AUTH_ENV, KEY_ENV, read_key_file

    if env.get(AUTH_ENV, "on").lower() == "off" or not env.get(KEY_ENV):
        return None
    return partition_of(read_key_file(env[KEY_ENV]))


def endpoint_profiles(partition: str) -> str:
    """The data_writer and data_reader profiles that put :data:`PARTITIONED_TOPICS` into
    ``partition`` (rmw_fastrtps takes a profile named as the topic for its endpoints, in
    place of the default profile: each repeats the default's settings)."""
    prop = ("      <propertiesPolicy><properties><property><name>partitions</name>"
            f"<value>{partition}</value></property></properties></propertiesPolicy>\n")
    out = []
    for topic in PARTITIONED_TOPICS:
        out.append(f'    <data_writer profile_name="{topic}">\n{_WRITER_BODY}{prop}'
                   "    </data_writer>\n")
        out.append(f'    <data_reader profile_name="{topic}">\n{_READER_BODY}{prop}'
                   "    </data_reader>\n")
    return "".join(out)


#: The participant ids of a domain: those whose unicast ports (:func:`unicast_ports`) fall
#: in the domain's 250 ports (id 120's would be the next domain's discovery ports).
DOMAIN_PARTICIPANT_IDS = range(0, 120)
#: Participant ids given to restarted processes (:func:`private_profile`): above the ids
#: Fast DDS hands out to a graph's own participants (0, 1, ... in start order).
RESTART_PARTICIPANT_IDS = range(60, DOMAIN_PARTICIPANT_IDS.stop)
#: Participant ids of the project's command-line tools (``hexapod status``, ``hexapod
#: switch``): between a graph's own ids and :data:`RESTART_PARTICIPANT_IDS`.
TOOL_PARTICIPANT_IDS = range(20, 60)
#: Participant ids of nodes started by hand (not by the graph launcher).
HAND_PARTICIPANT_IDS = DOMAIN_PARTICIPANT_IDS
#: Where Fast DDS keeps its shared-memory ports (``fastrtps_port<N>``).
SHM_DIR = Path("/dev/shm")


def unicast_ports(domain_id: int, participant_id: int) -> tuple[int, int]:
    """The metatraffic and user-data unicast ports of a participant (RTPS 2.x port mapping
    with its default constants: 7400 + 250 domain + 10 (or 11) + 2 participant); Fast DDS
    names its shared-memory ports by them."""
    base = 7400 + 250 * domain_id + 2 * participant_id
    return base + 10, base + 11


def unused_participant_id(domain_id: int, ids: range,
                          shm_dir: Path | None = None) -> int | None:
    """The first id of ``ids`` whose shared-memory ports do not exist in ``shm_dir``
    (default :data:`SHM_DIR`); None if every one does.

    Fast DDS gives a new participant the first id whose ports no live process holds, which
    after a SIGKILL is the dead process's: its shared-memory ports are still there, as the
    dead process left them, and the live participants still send to them until the dead
    one's lease ends (5 s), and keep them as they are after that (see
    :data:`FASTDDS_PROFILE`). A ``hexapod status`` started in that window took the id of a
    controller killed just before and saw no /hexapod/status in 3 runs of 5 (sometimes no
    node at all); with an id whose ports did not exist, 6 of 6 saw it within ~1.3 s.
    A port file left by a live process or by one long dead both mean "taken"; two new
    processes that pick the same id at once are harmless (Fast DDS moves the second one's
    ports, as for an id a live process holds)."""
    folder = SHM_DIR if shm_dir is None else shm_dir
    for pid in ids:
        if not any((folder / f"fastrtps_port{port}").exists()
                   for port in unicast_ports(domain_id, pid)):
            return pid
    return None


def shm_locks(pid: int, proc_dir: Path = Path("/proc")) -> list[Path]:
    """The lock files (``<SHM_DIR>/fastrtps_*_el``) that live process ``pid`` holds open:
    one per shared-memory port it listens on (``fastrtps_port<N>_el``) and one for its own
    segment. Empty if the process is gone (or has no participant yet)."""
    found = []
    try:
        fds = list((proc_dir / str(pid) / "fd").iterdir())
    except OSError:
        return []
    for fd in fds:
        try:
            target = Path(os.readlink(fd))
        except OSError:
            continue
        if target.parent == SHM_DIR and target.name.startswith("fastrtps_") \
                and target.name.endswith("_el"):
            found.append(target)
    return sorted(set(found))


class PortFence:
    """Holds the locks of shared-memory ports whose listener was killed (and of its
    segment), so that no new participant takes them (see :data:`FASTDDS_PROFILE`): a process
    that finds the lock of an id's port taken moves on to the next id. Released by
    :meth:`release` (or with the process that holds it)."""

    def __init__(self) -> None:
        self._held: dict[Path, IO[bytes]] = {}

    def hold(self, locks: Iterable[Path]) -> list[Path]:
        """Take the free ones of ``locks`` (exclusive, non-blocking); those now held. A
        lock another process holds (a live listener, or a process that took the id in the
        meantime) is left alone."""
        taken = []
        for path in locks:
            if path in self._held:
                continue
            try:
                f = open(path, "rb")
            except OSError:
                continue
            try:
                fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                f.close()
                continue
            self._held[path] = f
            taken.append(path)
        return taken

    @property
    def held(self) -> list[Path]:
        """The lock files held."""
        return sorted(self._held)

    def release(self, remove: bool = False) -> None:
        """Let every lock go; with ``remove``, first delete their files (a port, its lock
        and its mutex; a segment and its lock), once no process that used them is left: a
        process that takes the id later then makes a fresh port instead of opening the dead
        one, and the dead process's 8 MB segment does not stay in memory."""
        for path, f in self._held.items():
            if remove:
                port = path.name[:-len("_el")]
                for name in (port, path.name, f"sem.{port}_mutex"):
                    with contextlib.suppress(OSError):
                        (path.parent / name).unlink()
            f.close()
        self._held.clear()


def remove_dead_shm(domain_id: int, min_age: float = 60.0,
                    shm_dir: Path | None = None) -> list[str]:
    """Delete the shared-memory ports of ``domain_id`` and the segments (any domain) that a
    process killed without cleaning up left behind: their lock file exists, nobody holds
    its lock, and it is older than ``min_age`` s (a process creating its port takes the
    lock right after creating the file). Such a port is full of what its dead listener
    never took, and a process that takes its id later opens it as it is and hears nothing
    until its senders give up on it (:data:`HEALTHY_CHECK_MS`). Files of other users
    are left alone. The names of the ports and segments removed."""
    folder = SHM_DIR if shm_dir is None else shm_dir
    ports = {f"fastrtps_port{port}" for pid in DOMAIN_PARTICIPANT_IDS
             for port in unicast_ports(domain_id, pid)}
    fence = PortFence()
    removed = []
    try:
        locks = list(folder.glob("fastrtps_*_el"))
    except OSError:
        return []
    now = time.time()
    for lock in locks:
        base = lock.name[:-len("_el")]
        if base not in ports and not re.fullmatch(r"fastrtps_[0-9a-f]{16}", base):
            continue
        try:
            info = lock.stat()
        except OSError:
            continue
        if now - info.st_mtime < min_age or info.st_uid != os.getuid():
            continue
        if fence.hold([lock]):
            removed.append(base)
    fence.release(remove=True)
    return removed


def domain_id_from_env(env: Mapping[str, str] = os.environ) -> int:
    """``ROS_DOMAIN_ID`` of ``env`` as rclpy reads it (0 when unset or empty)."""
    value = env.get("ROS_DOMAIN_ID", "").strip()
    return int(value) if value.isdigit() else 0


def private_profile(directory: str | os.PathLike[str] | None = None,
                    remove_at_exit: bool = False, participant_id: int | None = None,
                    partition: str | None = None) -> Path:
    """Write :data:`FASTDDS_PROFILE` to ``directory`` (default: a new private temporary
    directory, mode 0700) as a file only its owner can read and write; its path.
    ``partition``: the run's tick topics in that DDS partition (:data:`PARTITIONED_TOPICS`;
    None: the default partition, as with ``HEXAPOD_AUTH=off``).

    ``participant_id`` fixes the participant's id, hence its ports (default: the first one
    free). A process started in place of one that was SIGKILLed would otherwise take the
    dead one's id and open its shared-memory port as the dead process left it; a recorder
    restarted that way sometimes never received a sample (1 run of 8 of the recorder-kill
    test: its shared-memory receive thread never woke), so the launcher gives restarted
    processes ids of their own (:data:`RESTART_PARTICIPANT_IDS`)."""
    made = directory is None
    folder = Path(tempfile.mkdtemp(prefix="hexapod_dds_") if made else directory)
    text, name = FASTDDS_PROFILE, "fastdds_profile.xml"
    text = text.replace("<!--endpoints-->", endpoint_profiles(partition) if partition else "")
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


__all__ = ["ANNOUNCE_S", "DOMAIN_PARTICIPANT_IDS", "FASTDDS_PROFILE", "HAND_PARTICIPANT_IDS",
           "HEALTHY_CHECK_MS", "LEASE_S", "PARTITIONED_TOPICS", "PORT_QUEUE", "PortFence",
           "READER_MAX_SAMPLES", "endpoint_profiles", "partition_of", "run_partition",
           "RESTART_PARTICIPANT_IDS", "SHM_DIR", "TOOL_PARTICIPANT_IDS", "domain_id_from_env",
           "private_profile", "remove_dead_shm", "shm_locks", "unicast_ports",
           "unused_participant_id"]
