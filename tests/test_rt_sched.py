"""The control-path threads that rt_priority puts under SCHED_FIFO (runtime/rt_sched.py)."""
from __future__ import annotations

import os
import threading

from hexapod_common.runtime.rt_sched import control_path_threads, dds_thread


def test_main_comes_first_and_only_fast_dds_receive_and_event_threads_follow():
    ready, done = threading.Event(), threading.Event()
    tids: list[int] = []

    def worker(name: str) -> None:
        tid = threading.get_native_id()
        with open(f"/proc/self/task/{tid}/comm", "w") as f:  # as Fast DDS names its threads
            f.write(name)
        tids.append(tid)
        if len(tids) == 3:
            ready.set()
        done.wait(10)

    threads = [threading.Thread(target=worker, args=(n,)) for n in
               ("dds.shm.7001", "dds.shm.wdog", "dds.ev.0")]
    for t in threads:
        t.start()
    try:
        assert ready.wait(10)
        got = control_path_threads()
        # The main thread first whatever its id (ids are not ordered by age once the
        # kernel's pid counter wraps: a CI run once logged "SCHED_FIFO for dds.ev.0, ...,
        # main").
        assert got[0] == (os.getpid(), "main")
        names = [n for _, n in got[1:]]
        assert sorted(names) == ["dds.ev.0", "dds.shm.7001"]  # not the watchdog
        assert all(dds_thread(n) for n in names)
        assert control_path_threads(main=False) == got[1:]
    finally:
        done.set()
        for t in threads:
            t.join()
