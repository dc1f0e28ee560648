"""Entry points forked by tests/test_node_fork.py (importable by the fork server: a module,
not a test)."""
from __future__ import annotations

import ctypes
import json
import os
import signal
import sys
import time


def report(path: str) -> int:
    """Write what the process runs with to ``path``, a line on stdout and on stderr; 3."""
    name = ctypes.create_string_buffer(16)
    ctypes.CDLL(None).prctl(16, name, 0, 0, 0)  # PR_GET_NAME
    with open(path, "w") as f:
        json.dump({"argv": sys.argv, "env": os.environ.get("FORK_TEST", ""),
                   "pid": os.getpid(), "sid": os.getsid(0), "nice": os.nice(0),
                   "name": name.value.decode(), "cwd": os.getcwd(),
                   "cmdline": open("/proc/self/cmdline", "rb").read().decode()}, f)
    print("on stdout")
    print("on stderr", file=sys.stderr)
    return 3


def wait_for_term(path: str) -> int:
    """Sleep until SIGTERM, then write ``term`` to ``path``; 0."""
    def on_term(signum: int, frame: object) -> None:
        with open(path, "w") as f:
            f.write("term")
        sys.exit(0)
    signal.signal(signal.SIGTERM, on_term)
    with open(path + ".ready", "w") as f:
        f.write(str(os.getpid()))
    while True:
        time.sleep(0.05)
