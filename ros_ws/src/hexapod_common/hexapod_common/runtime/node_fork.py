"""Node processes forked from a parent that has imported them already (Python's forkserver).

A node started as a new interpreter spends ~0.8 CPU s before it does any work: Python,
numpy, numba and rclpy imports (~0.55 s) and numba loading its compiled kernels from its
cache (~0.2 s); a graph starts five of them. :func:`start` asks the standard library's
fork server (``multiprocessing`` "forkserver" start method, one per launcher process) to
fork the node instead: the server imported the node modules once (``preload``), so a node
costs its own set-up only. Each forked node gets what ``subprocess.Popen`` would give it:
its command line (``sys.argv``, read by ``rclpy.init``), its environment, its log on
stdout and stderr (unbuffered), its own session, its niceness and the working directory of
the launcher; its process name (``ps``, ``top``: the kernel keeps 15 characters) is the
node's name, and so is its command line (``ps -f``, ``pgrep -f``, ``/proc/<pid>/cmdline``:
setproctitle rewrites the one the fork server had; ``sys.argv`` keeps the ROS arguments).

Two departures from a plain ``multiprocessing.Process``, both for "no node outlives its
launcher" (lifeline.py): the node closes its copy of the server's "alive" pipe (else the
server would wait for every node before it exits), and it asks for SIGTERM when the server
(its parent, which ends with the launcher) dies. At the end, the node runs the interpreter's
exit handlers (``atexit``), as a node started as ``python -c`` would.

:class:`ForkedNode` is the launcher's handle, with the part of ``subprocess.Popen``'s
interface the launcher and the tests use (``pid``, ``poll``, ``wait``, ``send_signal``,
``terminate``, ``kill``, ``returncode``); exit codes as Popen's (``-N`` for signal N).
"""
from __future__ import annotations

import atexit
import ctypes
import importlib
import io
import multiprocessing
import multiprocessing.forkserver
import os
import signal
import subprocess
import sys
from collections.abc import Mapping, Sequence

import setproctitle

from .lifeline import die_with_parent

PR_SET_NAME = 15


class ForkedNode:
    """A node process forked by the fork server (see the module's docstring)."""

    def __init__(self, process: multiprocessing.process.BaseProcess) -> None:
        self._process = process
        pid = process.pid
        assert pid is not None
        self.pid: int = pid

    @property
    def returncode(self) -> int | None:
        return self._process.exitcode

    def poll(self) -> int | None:
        """The exit code, None while the node runs."""
        return self._process.exitcode

    def wait(self, timeout: float | None = None) -> int:
        """Wait for the end (at most ``timeout`` s: ``subprocess.TimeoutExpired``)."""
        self._process.join(timeout)
        code = self._process.exitcode
        if code is None:
            raise subprocess.TimeoutExpired(f"node process {self.pid}", timeout or 0.0)
        return code

    def send_signal(self, sig: int) -> None:
        if self._process.exitcode is None:
            os.kill(self.pid, sig)

    def terminate(self) -> None:
        self.send_signal(signal.SIGTERM)

    def kill(self) -> None:
        self.send_signal(signal.SIGKILL)


def start(module: str, func: str, call_args: Sequence[str], argv: Sequence[str],
          env: Mapping[str, str], log: str, nice: int, name: str,
          preload: Sequence[str]) -> ForkedNode:
    """Fork ``module.func(*call_args)`` as node process ``name`` with ``sys.argv[1:] =
    argv``, environment ``env``, stdout and stderr appended to the file ``log`` and niceness
    ``nice``; the fork server (started on first use) imports ``preload`` first."""
    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload([__name__, *preload])
    process = ctx.Process(target=_node_main, name=name, daemon=True,
                          args=(module, func, tuple(call_args), tuple(argv), dict(env), log,
                                nice, name))
    process.start()
    return ForkedNode(process)


def _node_main(module: str, func: str, call_args: tuple[str, ...], argv: tuple[str, ...],
               env: dict[str, str], log: str, nice: int, name: str) -> None:
    """The forked node: its process set up as ``subprocess.Popen`` would, then its main."""
    server = os.getppid()
    alive = multiprocessing.forkserver._forkserver._forkserver_alive_fd  # type: ignore[attr-defined]
    if alive is not None:
        os.close(alive)
    os.setsid()
    fd = os.open(log, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    for target in (1, 2):
        os.dup2(fd, target)
    os.close(fd)
    sys.stdout = io.TextIOWrapper(io.FileIO(1, "w", closefd=False), write_through=True)
    sys.stderr = io.TextIOWrapper(io.FileIO(2, "w", closefd=False), write_through=True,
                                  errors="backslashreplace")
    # first: setproctitle finds the command line's memory next to the environment's, which
    # the clear() below moves. The node's name alone: rcl names the node's log file after
    # the program's name, read from the same memory (the ROS arguments made it too long)
    setproctitle.setproctitle(name)
    os.environ.clear()
    os.environ.update(env)
    if nice:
        os.nice(nice)
    try:
        ctypes.CDLL(None).prctl(PR_SET_NAME, name.encode()[:15], 0, 0, 0)
    except (OSError, AttributeError):
        pass  # (setproctitle set it too; this also where setproctitle could not)
    die_with_parent(parent=server)
    sys.argv = ["-c", *argv]
    try:
        code = getattr(importlib.import_module(module), func)(*call_args)
    finally:
        atexit._run_exitfuncs()
    sys.exit(code)


__all__ = ["ForkedNode", "start"]
