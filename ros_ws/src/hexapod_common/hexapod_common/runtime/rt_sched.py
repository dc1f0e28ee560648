"""Real-time scheduling of a node's control path (the ``rt_priority`` node parameter).

In realtime mode a tick's command must be back within one control period (1 ms at 1 kHz):
the state goes out, the controller wakes, computes and answers, the sim wakes and applies
it. Each hop wakes two threads: Fast DDS's shared-memory receive thread of the reading
process (it takes the sample off the port and signals the wait set), then the node's main
thread. On a 2-core machine running the five nodes (about 1.4 cores busy), a woken thread
waited 1-2 ms for a core often enough that only 83-89 % of ticks were on time, whatever the
nodes' own costs (docs/benchmarks.md). What real-time ROS 2 control does (ros2_control's
controller manager, the ROS 2 real-time guides) fixes it: the threads of the control path
run under ``SCHED_FIFO``, so a waking one preempts everything else at once: 99 % on time on
the same machine, also while switching.

:func:`make_realtime` puts this process's main thread and its Fast DDS threads that the
loop waits on (shared-memory receive threads ``dds.shm.<port>``, not the watchdog; the
event thread ``dds.ev.<n>``) under ``SCHED_FIFO`` at a priority. The trajectory generator is
on the control path too: it publishes 50 ticks ahead, but with its main thread under normal
scheduling on a busy machine it was starved for 60-100 ms at a time and the controller in
charge waited for its references (75-2900 late ticks in 10 s, against 76-1600 with it under
SCHED_FIFO, interleaved runs on one machine); on a machine the 1 kHz graph overloads, it ran
only every 0.2-1.3 s, the controller waited for its reference at 4354-4996 of 5000 ticks
(11 with it under SCHED_FIFO) and gave the oldest waiting states up, the switch tick among
them. The price on such a machine: the real-time threads leave other processes little CPU
(a new ROS participant did not discover the sim's services within 60 s there, with the
generator under SCHED_FIFO or not). The other nodes (recorder, markers, Foxglove
bridge) do the same for their Fast DDS threads only (their main threads keep normal
scheduling): a writer's synchronous publish takes locks
(the reader's port, the writer's history) that those threads also take, and one of them
preempted while holding it made the sim's publish wait up to ~1 ms (priority inversion:
25-89 late ticks in 10 s with only the control path under SCHED_FIFO, 6-28 with every
node's DDS threads too). These threads and the control path sleep between ticks, so the
rest is not starved (the kernel also keeps 5 % of each second for non-real-time threads).
It needs the privilege: CAP_SYS_NICE or an rtprio limit (``ulimit -r``, e.g. a line
``@realtime - rtprio 98`` in ``/etc/security/limits.d/``); without it the node says so in
one warning and runs with normal scheduling.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

#: The largest priority accepted (99 is left to the kernel's own threads' watchdogs).
MAX_PRIORITY = 98
#: What to do when it is not permitted (quoted in warnings).
HOW_TO_PERMIT = ("needs CAP_SYS_NICE or an rtprio limit: `ulimit -r`, e.g. "
                 "'@realtime - rtprio 98' in /etc/security/limits.d/")


class RealtimeNotPermitted(OSError):
    """SCHED_FIFO was refused (no CAP_SYS_NICE, rtprio limit too low)."""


def dds_thread(name: str) -> bool:
    """Whether a thread named ``name`` is one of Fast DDS's that the loop waits on: the
    shared-memory receive threads (``dds.shm.<port>``; not the watchdog) and the event
    thread (``dds.ev.<n>``: heartbeats, acknowledgements, timers)."""
    return (name.startswith("dds.shm.") and name != "dds.shm.wdog") or name.startswith("dds.ev.")


def control_path_threads(pid: int | None = None, main: bool = True) -> list[tuple[int, str]]:
    """(thread id, name) of the main thread (named ``main``, first; unless ``main`` is
    False) and the Fast DDS threads (:func:`dds_thread`, by thread id) of process ``pid``
    (default: this one). (Thread ids are not ordered by age: once the kernel's pid counter
    wraps, a thread made after the main one may have a lower id.)"""
    pid = os.getpid() if pid is None else pid
    out = [(pid, "main")] if main else []
    for task in sorted(Path(f"/proc/{pid}/task").iterdir(), key=lambda p: int(p.name)):
        tid = int(task.name)
        if tid == pid:
            continue
        try:
            name = (task / "comm").read_text().strip()
        except OSError:  # the thread ended meanwhile
            continue
        if dds_thread(name):
            out.append((tid, name))
    return out


class ControlPath:
    """The control-path threads of this process (:func:`control_path_threads`, listed once)
    and their SCHED_FIFO priority."""

    def __init__(self, main: bool = True) -> None:
        self.main = main
        self.threads = control_path_threads(main=main)
        self.priority = 0

    def refresh(self) -> list[str]:
        """Put the control-path threads made since the list was taken (Fast DDS opens a
        shared-memory receive port, and its thread, when it needs one, e.g. once a peer
        matched) under the same priority; their names."""
        if not self.priority:
            return []
        known = {tid for tid, _ in self.threads}
        added = []
        for tid, name in control_path_threads(main=self.main):
            if tid in known:
                continue
            try:
                os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(self.priority))
            except (ProcessLookupError, PermissionError):  # gone, or no longer permitted
                continue
            self.threads.append((tid, name))
            added.append(name)
        return added

    @property
    def names(self) -> list[str]:
        """The threads' names."""
        return [name for _, name in self.threads]

    def set(self, priority: int) -> None:
        """SCHED_FIFO at ``priority`` (1..98) for every thread, or raise
        RealtimeNotPermitted with nothing changed."""
        if not 1 <= priority <= MAX_PRIORITY:
            raise ValueError(f"priority {priority} outside [1, {MAX_PRIORITY}]")
        if priority == self.priority:
            return
        done: list[int] = []
        gone: list[int] = []
        for tid, _ in self.threads:
            try:
                os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(priority))
            except ProcessLookupError:  # the thread ended (its transport closed)
                gone.append(tid)
                continue
            except PermissionError as err:
                for t in done:  # all or nothing: back to what they had
                    if self.priority:
                        os.sched_setscheduler(t, os.SCHED_FIFO, os.sched_param(self.priority))
                    else:
                        os.sched_setscheduler(t, os.SCHED_OTHER, os.sched_param(0))
                raise RealtimeNotPermitted(f"SCHED_FIFO priority {priority} refused "
                                           f"({err.strerror}): {HOW_TO_PERMIT}") from None
            done.append(tid)
        self.threads = [t for t in self.threads if t[0] not in gone]
        self.priority = priority


def refresh_once(node: Any) -> None:
    """At a node's first tick: :meth:`ControlPath.refresh` of its ``rt`` (if any), once, and
    say in its log which threads joined (``node.rt``, ``node.log``)."""
    path = getattr(node, "rt", None)
    node.rt_refreshed = True
    if path is not None:
        late = path.refresh()
        if late:
            node.log.info(f"rt_priority: SCHED_FIFO also for {', '.join(late)}")


def make_realtime(priority: int, main: bool = True) -> ControlPath:
    """Put :func:`control_path_threads` under SCHED_FIFO at ``priority`` (1..98); raises
    RealtimeNotPermitted (nothing changed) if refused."""
    path = ControlPath(main)
    path.set(priority)
    return path


def realtime_permitted(priority: int) -> bool:
    """Whether this process may use SCHED_FIFO at ``priority`` (tried on the calling thread,
    which is put back to normal scheduling)."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except PermissionError:
        return False
    os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    return True


def use_rt_priority(node: Any, log: Any, main: bool = True) -> ControlPath | None:
    """Declare the node's ``rt_priority`` parameter and apply it (to the main thread too
    unless ``main`` is False); say in the log what was set, or why not (one warning). The
    threads if they run under SCHED_FIFO, else None (``rt_priority`` 0, or not
    permitted)."""
    from .ros_params import declare_node_param

    priority = int(declare_node_param(node, "rt_priority"))
    if priority == 0:
        return None
    try:
        path = make_realtime(priority, main)
    except RealtimeNotPermitted as err:
        log.warning(f"rt_priority {priority} not applied: {err}; running with normal "
                    f"scheduling (realtime mode may miss deadlines)")
        return None
    log.info(f"rt_priority {priority}: SCHED_FIFO for {', '.join(path.names)}")
    return path


__all__ = ["HOW_TO_PERMIT", "MAX_PRIORITY", "ControlPath", "RealtimeNotPermitted",
           "control_path_threads", "dds_thread",
           "make_realtime", "realtime_permitted", "refresh_once", "use_rt_priority"]
