"""Run a bag-writing script in a child process and SIGKILL it once its MCAP has grown."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path


def write_then_kill(script: str, path: Path, min_size: int, timeout: float = 60.0) -> None:
    """Run ``script`` (Python source, given the bag directory as argv[1]) until
    ``path/<name>_0.mcap`` is larger than ``min_size`` bytes, then SIGKILL it: no close, no
    summary written by the writer itself."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    proc = subprocess.Popen([sys.executable, "-c", script, str(path)], env=env)
    mcap_file = path / f"{path.name}_0.mcap"
    deadline = time.monotonic() + timeout
    try:
        while not (mcap_file.exists() and mcap_file.stat().st_size > min_size):
            assert proc.poll() is None, "writer process died on its own"
            assert time.monotonic() < deadline, f"writer wrote {min_size} bytes in {timeout} s"
            time.sleep(0.01)
    finally:
        proc.kill()
        proc.wait()
    assert proc.returncode == -signal.SIGKILL
