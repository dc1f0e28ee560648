"""scripts/setup.sh talks: each step that runs says when it starts and how long it took,
also in the quiet mode the wrappers use (on stderr); nothing when nothing is to do.

Run on a throwaway copy of the project's layout (the script, a one-line lock, an empty
workspace): the real steps (a venv, pip, colcon) run for real, in seconds."""
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
STEPS = ("[1/3] creating .venv", "[2/3] pip install", "[3/3] colcon build")
ENDS = (r"\[1/3\] \.venv created \(\d+ s\)", r"\[2/3\] python deps ready \(\d+ s\)",
        r"\[3/3\] workspace built \(\d+ s\)")


def _project(tmp: Path) -> Path:
    root = tmp / "project"
    (root / "scripts").mkdir(parents=True)
    shutil.copy(ROOT / "scripts" / "setup.sh", root / "scripts" / "setup.sh")
    # pip is in every fresh venv: "already satisfied", no index needed
    (root / "requirements.lock").write_text("pip\n")
    (root / "requirements.txt").write_text("pip\n")
    (root / "ros_ws" / "src").mkdir(parents=True)
    return root


def _setup(root: Path, *args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "HEXAPOD_PYTHON": sys.executable, "PIP_NO_INDEX": "1",
           "PIP_DISABLE_PIP_VERSION_CHECK": "1"}
    return subprocess.run([str(root / "scripts" / "setup.sh"), *args], env=env,
                          capture_output=True, text=True, timeout=300)


def test_quiet_setup_says_each_step_that_runs_and_nothing_when_done(tmp_path):
    if shutil.which("colcon") is None:
        pytest.skip("colcon is not on PATH (source scripts/env.sh)")
    root = _project(tmp_path)
    r = _setup(root, "--quiet")
    assert r.returncode == 0, r.stderr
    assert r.stdout == ""  # stdout stays the wrapped command's (e.g. --json)
    lines = r.stderr.splitlines()
    starts = [next(i for i, line in enumerate(lines) if line.startswith(f"setup: {s}"))
              for s in STEPS]
    ends = [next(i for i, line in enumerate(lines) if re.fullmatch(f"setup: {e}", line))
            for e in ENDS]
    assert starts[0] < ends[0] < starts[1] < ends[1] < starts[2] < ends[2], lines
    assert len(lines) == 6, lines
    assert (root / ".venv" / "bin" / "python").exists()
    assert (root / "ros_ws" / "install" / "local_setup.bash").exists()
    again = _setup(root, "--quiet")
    assert again.returncode == 0 and again.stdout == "" and again.stderr == ""
    # not quiet: on stdout, and only what runs: here nothing but the last line
    loud = _setup(root)
    assert loud.returncode == 0 and loud.stdout == "setup: ready: source scripts/env.sh\n"
