"""Is a node of the graph still alive? What a lockstep tick asks before it gives up waiting.

A process that is stopped (``kill -STOP``), starved by a busy machine or paging is alive
while it stays on the graph: the run waits for it. A node has left once its name is no
longer listed on the graph, i.e. its DDS participant's lease ran out (``dds_profile.LEASE_S``:
a process stopped longer than that is dropped by its peers and drops them when it resumes,
losing what was sent meanwhile, so waiting for it longer would wait for a message that
never comes). For the nodes the launcher started, it names their processes in a JSON file
(node name -> pid, the path in :data:`PIDS_ENV`), and a process's state in ``/proc`` says at
once that one has ended (a zombie, an ended child not yet reaped, is dead), without
waiting for its lease.
"""
from __future__ import annotations

import json
import os
from collections.abc import Callable, Iterable

#: The environment variable naming the launcher's file of node pids.
PIDS_ENV = "HEXAPOD_GRAPH_PIDS"


def process_alive(pid: int) -> bool:
    """Whether process ``pid`` exists and has not ended (running, sleeping or stopped)."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            stat = f.read()
    except FileNotFoundError:
        return False
    except OSError:  # no /proc: ask the kernel (a zombie then counts as alive)
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        except PermissionError:
            return True
        return True
    state = stat[stat.rfind(b")") + 2:][:1]  # the field after "(comm)"
    return state not in (b"Z", b"X", b"x")


def launcher_pids(path: str | None = None) -> dict[str, int]:
    """The launcher's node name -> pid (empty if there is no such file or it is unreadable:
    every node is then judged by the graph)."""
    path = path if path is not None else os.environ.get(PIDS_ENV)
    if not path:
        return {}
    try:
        with open(path) as f:
            doc = json.load(f)
    except (OSError, ValueError):
        return {}
    return {str(k): int(v) for k, v in doc.items()
            if isinstance(v, int) and not isinstance(v, bool)} if isinstance(doc, dict) else {}


class Liveness:
    """Whether nodes are alive: listed on the graph (``graph_nodes``: a callable giving the
    names on the graph) and, where the launcher named their process, that process not
    ended (asked first: it answers without the graph)."""

    def __init__(self, graph_nodes: Callable[[], Iterable[str]], path: str | None = None):
        self.graph_nodes = graph_nodes
        self.path = path if path is not None else os.environ.get(PIDS_ENV)
        self.pids: dict[str, int] = {}

    def alive(self, *nodes: str) -> bool:
        """True if every one of ``nodes`` is alive."""
        if self.path and any(n not in self.pids for n in nodes):
            self.pids = launcher_pids(self.path)  # written by then, or rewritten since
        for n in nodes:
            pid = self.pids.get(n)
            if pid is not None and not process_alive(pid):
                return False
        listed = set(self.graph_nodes())
        return all(n in listed for n in nodes)


__all__ = ["PIDS_ENV", "Liveness", "launcher_pids", "process_alive"]
