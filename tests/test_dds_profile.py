"""The graph's Fast DDS profile (hexapod_common/runtime/dds_profile.py): private, well-formed,
and with a participant id of its own for restarted processes and tools (never a SIGKILLed
process's, and after a SIGKILL not for other processes either: the fence)."""
from __future__ import annotations

import os
import stat
import time
import xml.etree.ElementTree as ET

import pytest

from hexapod_common.runtime.dds_profile import (ANNOUNCE_S, HEALTHY_CHECK_MS, LEASE_S,
                                                PORT_QUEUE, READER_MAX_SAMPLES,
                                                RESTART_PARTICIPANT_IDS, SHM_DIR,
                                                TOOL_PARTICIPANT_IDS, PortFence,
                                                domain_id_from_env, remove_dead_shm, shm_locks,
                                                private_profile, unicast_ports,
                                                unused_participant_id)

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
    # senders; the participants' lease ends before the port check (longer than Fast DDS's
    # 1 s; 10 s failed the test suite) can declare such a reader's port broken, so that its
    # port is never re-created, and it is announced several times per lease.
    path = private_profile(tmp_path)
    disc = _rtps(path).find("d:builtin/d:discovery_config", NS)

    def seconds(name: str) -> float:
        node = disc.find(f"d:{name}", NS)
        return int(node.find("d:sec", NS).text) + int(node.find("d:nanosec", NS).text) * 1e-9

    lease, announce = seconds("leaseDuration"), seconds("leaseAnnouncement")
    assert (lease, announce) == (LEASE_S, ANNOUNCE_S) == (5, 0.25)
    assert int(_shm(path).find("d:port_queue_capacity", NS).text) == PORT_QUEUE == 1024
    check = int(_shm(path).find("d:healthy_check_timeout_ms", NS).text)
    assert check == HEALTHY_CHECK_MS and 1000 * lease < check <= 6000 and lease >= 4 * announce


def test_a_reader_may_hold_as_many_untaken_samples_as_its_depth(tmp_path):
    from hexapod_common.core.topics import CONTROL_DEPTH, HISTORY_DEPTH, RECORD_DEPTH

    limits = ET.parse(private_profile(tmp_path)).getroot().find(
        "d:profiles/d:data_reader/d:topic/d:resourceLimitsQos", NS)
    assert int(limits.find("d:max_samples", NS).text) == READER_MAX_SAMPLES
    assert int(limits.find("d:max_samples_per_instance", NS).text) == READER_MAX_SAMPLES
    assert READER_MAX_SAMPLES >= max(RECORD_DEPTH, HISTORY_DEPTH, CONTROL_DEPTH)


def test_unicast_ports_follow_the_rtps_port_mapping():
    # Fast DDS's shared-memory port of domain 13's first participant is fastrtps_port10661
    assert unicast_ports(13, 0) == (10660, 10661)
    assert unicast_ports(0, 2) == (7414, 7415)


def test_a_new_process_never_takes_a_participant_id_whose_ports_exist(tmp_path):
    """A SIGKILLed process leaves its shared-memory ports behind; an id whose ports exist
    (live or dead) is skipped, whichever of its two ports is there."""
    ids = range(20, 24)
    assert unused_participant_id(7, ids, tmp_path) == 20
    (tmp_path / f"fastrtps_port{unicast_ports(7, 20)[1]}").touch()
    (tmp_path / f"fastrtps_port{unicast_ports(7, 21)[0]}").touch()
    (tmp_path / f"fastrtps_port{unicast_ports(8, 22)[1]}").touch()  # another domain's
    assert unused_participant_id(7, ids, tmp_path) == 22
    for i in ids:
        (tmp_path / f"fastrtps_port{unicast_ports(7, i)[1]}").touch()
    assert unused_participant_id(7, ids, tmp_path) is None


def test_a_hand_started_process_writes_its_profile_with_an_unused_participant_id(
        tmp_path, monkeypatch):
    import hexapod_common.runtime.dds_profile as dds
    from hexapod_common.runtime.hot_loop import configure_middleware

    monkeypatch.setattr(dds, "SHM_DIR", tmp_path)
    monkeypatch.setenv("ROS_DOMAIN_ID", "9")
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.delenv("FASTRTPS_DEFAULT_PROFILES_FILE", raising=False)  # restored after
    monkeypatch.setenv("RMW_FASTRTPS_PUBLICATION_MODE", "SYNCHRONOUS")
    (tmp_path / f"fastrtps_port{unicast_ports(9, 20)[1]}").touch()  # a killed tool's
    configure_middleware(TOOL_PARTICIPANT_IDS)
    path = os.environ["FASTRTPS_DEFAULT_PROFILES_FILE"]
    assert _rtps(path).find("d:participantID", NS).text == "21"
    assert domain_id_from_env({"ROS_DOMAIN_ID": " "}) == 0


def _locked_elsewhere(path):
    import fcntl

    with open(path, "rb") as f:
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            return True
        return False


def test_the_fence_holds_free_shm_locks_and_leaves_taken_ones_alone(tmp_path):
    import fcntl

    free, taken = tmp_path / "fastrtps_port1_el", tmp_path / "fastrtps_port3_el"
    free.touch()
    taken.touch()
    other = open(taken, "rb")
    fcntl.flock(other, fcntl.LOCK_EX)  # a live listener
    fence = PortFence()
    try:
        assert fence.hold([free, taken, tmp_path / "missing_el"]) == [free]
        assert fence.held == [free]
        assert _locked_elsewhere(free)  # a new participant cannot take that id
        assert fence.hold([free]) == []  # held once
    finally:
        fence.release()
        other.close()
    assert fence.held == [] and not _locked_elsewhere(free)


def test_shm_locks_are_the_shared_memory_lock_files_a_process_holds_open():
    import subprocess
    import sys

    name = SHM_DIR / f"fastrtps_port{900000 + os.getpid()}_el"
    child = subprocess.Popen([sys.executable, "-c",
                              f"import sys, time; f = open({str(name)!r}, 'a'); "
                              "g = open('/dev/null'); print('ready', flush=True); time.sleep(30)"],
                             stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout is not None and child.stdout.readline().strip() == "ready"
        assert shm_locks(child.pid) == [name]
    finally:
        child.kill()
        child.wait()
        name.unlink(missing_ok=True)
    assert shm_locks(child.pid) == []


def test_released_with_remove_the_dead_ports_files_go(tmp_path):
    lock = tmp_path / "fastrtps_port7411_el"
    files = [tmp_path / "fastrtps_port7411", lock, tmp_path / "sem.fastrtps_port7411_mutex"]
    segment = [tmp_path / "fastrtps_0c59c54c5ed398c8", tmp_path / "fastrtps_0c59c54c5ed398c8_el"]
    other = tmp_path / "fastrtps_port7413"  # another port: not touched
    for f in files + segment + [other]:
        f.touch()
    fence = PortFence()
    assert fence.hold([lock, segment[1]]) == [lock, segment[1]]
    fence.release(remove=True)
    assert not any(f.exists() for f in files + segment) and other.exists()


def test_dead_ports_of_the_domain_and_dead_segments_are_removed_and_nothing_else(tmp_path):
    import fcntl

    def make(base, age=120.0):
        for name in (base, f"{base}_el") + ((f"sem.{base}_mutex",) if "port" in base else ()):
            (tmp_path / name).touch()
            os.utime(tmp_path / name, (time.time() - age, time.time() - age))
        return base

    dead_port = make(f"fastrtps_port{unicast_ports(7, 3)[1]}")
    dead_segment = make("fastrtps_0c59c54c5ed398c8")
    other_domain = make(f"fastrtps_port{unicast_ports(8, 3)[1]}")
    young = make(f"fastrtps_port{unicast_ports(7, 4)[1]}", age=1.0)
    live = make(f"fastrtps_port{unicast_ports(7, 5)[1]}")
    clean_exit = f"fastrtps_port{unicast_ports(7, 6)[1]}"  # Fast DDS leaves it, no lock
    (tmp_path / clean_exit).touch()
    holder = open(tmp_path / f"{live}_el", "rb")
    fcntl.flock(holder, fcntl.LOCK_EX)
    try:
        removed = remove_dead_shm(7, shm_dir=tmp_path)
    finally:
        holder.close()
    assert sorted(removed) == sorted([dead_port, dead_segment])
    left = {p.name for p in tmp_path.iterdir()}
    assert not any(n.startswith(dead_port) or n.startswith(dead_segment)
                   or n == f"sem.{dead_port}_mutex" for n in left)
    for kept in (other_domain, young, live):
        assert {kept, f"{kept}_el", f"sem.{kept}_mutex"} <= left
    assert clean_exit in left


def test_the_launcher_looks_at_a_running_nodes_locks_until_two_looks_agree(
        tmp_path, monkeypatch):
    """GraphProcesses.poll notes a live node's shared-memory locks (for the fence if a
    signal kills it): every poll until two looks in a row agree, then every LOCKS_REFRESH
    s (a look reads /proc/<pid>/fd, ~0.5 ms; the watch loop polls every 0.1 s)."""
    import subprocess
    import sys
    from pathlib import Path
    from types import SimpleNamespace

    import hexapod_bringup.cmd_graph as cg

    looks = []
    answers = [[], [Path("/dev/shm/fastrtps_a_el")], [Path("/dev/shm/fastrtps_a_el")]]

    def fake_locks(pid):
        looks.append(pid)
        return answers[min(len(looks) - 1, len(answers) - 1)]
    monkeypatch.setattr(cg, "shm_locks", fake_locks)
    g = cg.GraphProcesses(tmp_path, env={"HEXAPOD_AUTH": "off"})
    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    g.procs["n"] = proc
    try:
        for _ in range(10):
            assert g.poll("n") is None
        assert len(looks) == 3  # empty, first list, the same list again: then it waits
        assert g._locks["n"] == answers[1]
        later = time.monotonic() + cg.LOCKS_REFRESH + 0.1
        monkeypatch.setattr(cg, "time", SimpleNamespace(monotonic=lambda: later))
        g.poll("n")
        assert len(looks) == 4
    finally:
        proc.kill()
        proc.wait()


def test_the_tick_topics_are_put_in_the_runs_partition_with_the_default_settings(tmp_path):
    """Every reader and writer of the tick topics gets a profile of its own (named as the
    topic: rmw_fastrtps takes it instead of the default) with the run's partition and the
    default profile's settings; nothing else is partitioned, and without a partition
    (HEXAPOD_AUTH=off) there is no such profile."""
    from hexapod_common.core import topics as T
    from hexapod_common.core.msg_auth import AUTH_ENV, KEY_ENV, new_key_file, read_key_file
    from hexapod_common.runtime.dds_profile import (PARTITIONED_TOPICS, partition_of,
                                                    run_partition)

    key_path = new_key_file(tmp_path)
    env = {KEY_ENV: str(key_path)}
    part = run_partition(env)
    assert part == partition_of(read_key_file(key_path)) and part.startswith("hexapod_")
    assert partition_of(os.urandom(32)) != part  # another run, another partition
    assert run_partition({**env, AUTH_ENV: "off"}) is None and run_partition({}) is None
    assert set(PARTITIONED_TOPICS) == {T.JOINT_STATES, T.FOOT_FORCES, T.HIP_STATES,
                                       T.REFERENCE, T.JOINT_COMMANDS, T.RECORDED}
    (tmp_path / "a").mkdir()
    profiles = ET.parse(private_profile(tmp_path / "a", partition=part)).getroot().find(
        "d:profiles", NS)
    default = {k: profiles.find(f"d:{k}[@is_default_profile='true']", NS)
               for k in ("data_writer", "data_reader")}
    for kind, base in default.items():
        named = {e.get("profile_name"): e for e in profiles.findall(f"d:{kind}", NS)
                 if e.get("is_default_profile") != "true"}
        assert set(named) == set(PARTITIONED_TOPICS), kind
        for topic, e in named.items():
            prop = e.find("d:propertiesPolicy/d:properties/d:property", NS)
            assert (prop.find("d:name", NS).text, prop.find("d:value", NS).text) == (
                "partitions", part), topic
            for child in base:  # the default's settings, repeated
                same = [ET.canonicalize(ET.tostring(x), strip_text=True)
                        for x in (e.find(child.tag), child)]
                assert same[0] == same[1], (topic, child.tag)
    open_root = ET.parse(private_profile(tmp_path)).getroot().find("d:profiles", NS)
    assert len(open_root.findall("d:data_writer", NS)) == 1
