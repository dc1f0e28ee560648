"""Run a bag-writing script in a child process and SIGKILL it once its MCAP has grown."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path


def write_then_kill(script: str, path: Path, min_size: int, timeout: float = 60.0,
                    between_writes: bool = False) -> None:
    """Run ``script`` (Python source, given the bag directory as argv[1]) until
    ``path/<name>_0.mcap`` is larger than ``min_size`` bytes, then SIGKILL it: no close, no
    summary written by the writer itself.

    The kill lands anywhere, inside a write of the file too (a starved writer spends longer
    in one: the window bag/writer.py documents), unless ``between_writes``: then the writer
    is stopped first (SIGSTOP takes effect when a write to a file returns, never inside it)
    and killed while stopped, so the kill lands between two writes."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    proc = subprocess.Popen([sys.executable, "-c", script, str(path)], env=env)
    mcap_file = path / f"{path.name}_0.mcap"
    deadline = time.monotonic() + timeout
    try:
        while not (mcap_file.exists() and mcap_file.stat().st_size > min_size):
            assert proc.poll() is None, "writer process died on its own"
            assert time.monotonic() < deadline, f"writer wrote {min_size} bytes in {timeout} s"
            time.sleep(0.01)
        if between_writes:
            proc.send_signal(signal.SIGSTOP)
            _wait_stopped(proc.pid)
    finally:
        proc.kill()
        proc.wait()
    assert proc.returncode == -signal.SIGKILL


def _wait_stopped(pid: int, timeout: float = 30.0) -> None:
    """Until process ``pid`` is stopped (state T in /proc/<pid>/stat)."""
    deadline = time.monotonic() + timeout
    stat = Path(f"/proc/{pid}/stat")
    while stat.read_text().rsplit(")", 1)[1].split()[0] != "T":
        assert time.monotonic() < deadline, f"process {pid} did not stop in {timeout} s"
        time.sleep(0.001)
