"""A small disk for full-disk tests: a tmpfs the test mounts itself (as root), else a file
size limit (``prlimit --fsize``) on the writing process, which makes its writes past that
size fail at the file layer (EFBIG) exactly where a full disk fails them (ENOSPC)."""
from __future__ import annotations

import contextlib
import os
import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import NamedTuple


class SmallDisk(NamedTuple):
    """Where to write, and the command prefix a writing process needs (empty on tmpfs)."""

    path: Path
    prefix: tuple[str, ...]
    kind: str
    """'tmpfs' or 'fsize'."""


@contextlib.contextmanager
def small_disk(where: Path, size: int) -> Iterator[SmallDisk]:
    """A directory at ``where`` that holds about ``size`` bytes.

    ``HEXAPOD_SMALL_DISK=fsize`` in the environment forces the file-size limit."""
    where.mkdir(parents=True, exist_ok=True)
    mounted = False
    if (os.geteuid() == 0 and shutil.which("mount")
            and os.environ.get("HEXAPOD_SMALL_DISK") != "fsize"):
        done = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs",
                               str(where)], capture_output=True, text=True)
        mounted = done.returncode == 0
    try:
        if mounted:
            yield SmallDisk(where, (), "tmpfs")
        else:
            prlimit = shutil.which("prlimit")
            assert prlimit, "neither a tmpfs mount (needs root) nor prlimit is available"
            yield SmallDisk(where, (prlimit, f"--fsize={size}"), "fsize")
    finally:
        if mounted:
            subprocess.run(["umount", "-l", str(where)], check=False)
