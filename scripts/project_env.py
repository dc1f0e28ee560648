"""Run a script of this directory inside the project's environment (for the graph
benchmarks, which start ROS nodes): set the project up if needed, then re-exec the script
with scripts/env.sh sourced (.venv and the ros_ws overlay)."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def reexec_in_env(script: str) -> None:
    """Return at once inside the project's venv; else set up and re-exec ``script``."""
    if os.environ.get("VIRTUAL_ENV") == str(ROOT / ".venv"):
        return
    subprocess.run([str(ROOT / "scripts" / "setup.sh"), "--quiet"], check=True)
    cmd = f'source "{ROOT}/scripts/env.sh" && exec python "$0" "$@"'
    os.execvp("bash", ["bash", "-c", cmd, script, *sys.argv[1:]])
