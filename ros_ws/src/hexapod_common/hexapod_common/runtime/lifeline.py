"""Node processes die with their launcher (Linux): no node outlives a ``kill -9`` of it.

:func:`die_with_parent` asks the kernel (``prctl(PR_SET_PDEATHSIG)``) to send this process
SIGTERM when its parent dies; the node then stops as on Ctrl-C (the recorder closes its
bag). If the parent is already gone by then (``HEXAPOD_PARENT_PID`` names the one
expected), the process exits at once. No ROS imports: called before anything else.
"""
from __future__ import annotations

import ctypes
import os
import signal
import sys

PR_SET_PDEATHSIG = 1
#: Environment variable with the pid of the launcher that started this node.
PARENT_ENV = "HEXAPOD_PARENT_PID"


def die_with_parent(sig: int = signal.SIGTERM, parent: int | None = None) -> bool:
    """Arrange for ``sig`` when the parent dies; False where prctl is not available.
    ``parent``: the pid of the parent expected (default: ``HEXAPOD_PARENT_PID``'s)."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(PR_SET_PDEATHSIG, int(sig), 0, 0, 0) != 0:
            return False
    except (OSError, AttributeError):
        return False
    expected = str(parent) if parent is not None else os.environ.get(PARENT_ENV, "")
    if expected.isdigit() and os.getppid() != int(expected):
        print("node: the launcher is gone before the node started: exiting", file=sys.stderr)
        os._exit(1)
    return True


__all__ = ["PARENT_ENV", "PR_SET_PDEATHSIG", "die_with_parent"]
