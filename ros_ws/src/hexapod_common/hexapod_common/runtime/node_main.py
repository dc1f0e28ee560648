"""The one ``main()`` of every node of the graph (ros2/examples' skeleton, with our hot loop).

:func:`run_node`: ``rclpy.init`` without rclpy's signal handlers (a bad ROS command line is
one line and exit code 2), build the node, log its pid, ROS_DOMAIN_ID and discovery range
(what the process runs with, whoever started it), SIGINT/SIGTERM stop its loop
(hot_loop.install_stop_signals), an optional start step, spin the loop; an error is one log
line and an exit code (2: bad parameters or no key, ``ParameterError``/``AuthError``; 1:
another error, a diverged model included); then the node's own finish step (summaries,
closing a bag; it may change the exit code), the loop and the node destroyed,
``rclpy.try_shutdown``.

Once the finish step is done, the node's work is saved: a teardown (node destruction, rclpy
and Fast DDS shutdown) that has not returned within :data:`TEARDOWN_S` ends the process with
the node's exit code and one log line. Under CPU load, beside peers killed by a signal, a
node was seen to hang there for 20 s and more after its summary; the launcher then killed it
and reported a node that died.
"""
from __future__ import annotations

import os
import sys
import threading
from collections.abc import Callable
from typing import Any, Protocol, TypeVar

from ..core.errors import DivergenceError, HexapodError, ParameterError
from ..core.msg_auth import AuthError
from .hot_loop import HotLoop, init_rclpy, install_stop_signals

#: Exit code of bad parameters, a bad command line or a missing key.
EXIT_BAD_SETTINGS = 2
#: Exit code of any other error (a diverged model included).
EXIT_ERROR = 1
#: Wall s the teardown after the finish step may take before the process ends without it.
TEARDOWN_S = 5.0


class _LoopNode(Protocol):
    loop: HotLoop

    def destroy_node(self) -> Any: ...


N = TypeVar("N", bound=_LoopNode)


def exit_code(err: BaseException) -> int:
    """The exit code of an error that ended a node."""
    return EXIT_BAD_SETTINGS if isinstance(err, (ParameterError, AuthError)) else EXIT_ERROR


def run_node(name: str, make: Callable[[], N], args: list[str] | None = None, *,
             start: Callable[[N], None] | None = None,
             finish: Callable[[N, int], int] | None = None,
             errors: tuple[type[Exception], ...] = (HexapodError,)) -> int:
    """Run the node ``make()`` named ``name`` until its loop stops; its exit code.

    ``start(node)`` runs before the loop spins; ``finish(node, code)`` runs at the end
    whatever happened (also after an error) and returns the exit code; ``errors``: the
    exception types that end the node with one log line (beside ``HexapodError``)."""
    import rclpy
    from rclpy.executors import ExternalShutdownException

    if not init_rclpy(args, name):
        return EXIT_BAD_SETTINGS
    node: N | None = None
    watchdog: threading.Timer | None = None
    code = 0
    caught: tuple[type[Exception], ...] = (HexapodError, *errors)
    try:
        node = make()
        rclpy.logging.get_logger(name).info(
            f"pid {os.getpid()}, ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID', '0')}, "
            f"discovery {os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE') or 'SUBNET'}")
        install_stop_signals(node.loop)
        if start is not None:
            start(node)
        node.loop.spin()
    except DivergenceError as err:
        rclpy.logging.get_logger(name).error(f"{err}: stopping")
        code = EXIT_ERROR
    except caught as err:
        rclpy.logging.get_logger(name).error(str(err))
        code = exit_code(err)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            try:
                if finish is not None:
                    code = finish(node, code)
            finally:
                watchdog = _teardown_watchdog(name, code)
                node.loop.destroy()
                node.destroy_node()
        rclpy.try_shutdown()
        if watchdog is not None:
            watchdog.cancel()
    return code


def _teardown_watchdog(name: str, code: int) -> threading.Timer:
    """A started timer that ends the process with ``code`` after :data:`TEARDOWN_S` s."""
    def expire() -> None:
        print(f"[{name}] teardown did not end within {TEARDOWN_S:g} s: exiting "
              f"(code {code})", file=sys.stderr, flush=True)
        sys.stdout.flush()
        os._exit(code)

    timer = threading.Timer(TEARDOWN_S, expire)
    timer.daemon = True
    timer.start()
    return timer


__all__ = ["EXIT_BAD_SETTINGS", "EXIT_ERROR", "exit_code", "run_node"]
