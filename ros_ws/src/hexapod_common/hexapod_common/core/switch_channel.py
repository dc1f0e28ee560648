"""A private local channel to the running sim, so that `hexapod switch` and `hexapod status`
need no ROS context.

A new DDS participant per call cost 1-4 s (rclpy's start, discovery, service matching: 2.7-6.4 s
for a status on a busy machine) and, while the graph's nodes discovered it, about 10 % of the
realtime ticks. Instead the sim listens on a UNIX datagram socket,
``<runtime dir>/sim-<ROS_DOMAIN_ID>.sock``; the runtime dir is ``$XDG_RUNTIME_DIR/hexapod``
or ``/tmp/hexapod-<uid>``, created with mode 0700 and refused unless it belongs to this user
with that mode and is no symlink (as tmux does), so only this user's processes can send a
request. One request, one datagram: ``switch pd_p`` or ``status``; one answer: ``ok <text>`` or
``error <text>`` (a status: ``ok <JSON>``, up to :data:`MAX_REPLY` bytes). The sim takes
requests at its tick boundaries (and while no tick goes out, every 50 ms) and runs a switch
through the same parameter checks as a ``run.controller`` set over ROS
(hexapod_sim/channel_service.py). ROS-free.
"""
from __future__ import annotations

import os
import socket
import stat
import time
from pathlib import Path

from .errors import HexapodError

MAX_DATAGRAM = 4096
#: Longest answer (bytes): a status with every node, drop count and outside publisher.
MAX_REPLY = 65536


class ChannelError(HexapodError):
    """The switch channel is unsafe to use or the sim did not answer."""


def runtime_dir(create: bool = True) -> Path:
    """This user's private runtime directory (0700, checked); ChannelError if unsafe."""
    base = os.environ.get("XDG_RUNTIME_DIR")
    d = Path(base) / "hexapod" if base else Path("/tmp") / f"hexapod-{os.getuid()}"
    if create:
        try:
            d.mkdir(mode=0o700, exist_ok=True)
        except OSError as err:
            raise ChannelError(f"cannot create {d}: {err.strerror}") from err
    try:
        st = d.lstat()
    except FileNotFoundError:
        return d
    if (not stat.S_ISDIR(st.st_mode) or st.st_uid != os.getuid()
            or stat.S_IMODE(st.st_mode) != 0o700):
        raise ChannelError(f"{d} must be a directory of this user with mode 0700 (found uid "
                           f"{st.st_uid}, mode {stat.S_IMODE(st.st_mode):04o}): remove it")
    return d


def socket_path(domain_id: str | int) -> Path:
    """The sim's socket for ``ROS_DOMAIN_ID`` = ``domain_id``."""
    return runtime_dir(create=False) / f"sim-{domain_id}.sock"


class SwitchServer:
    """The sim's end: a non-blocking datagram socket polled at tick boundaries."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self.sock.setblocking(False)

    @classmethod
    def open(cls, domain_id: str | int) -> "SwitchServer":
        """Bind the socket of ``domain_id`` (a stale one is replaced); ChannelError if a live
        sim already holds it or the runtime dir is unsafe."""
        runtime_dir(create=True)
        path = socket_path(domain_id)
        if path.exists():
            probe = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
            try:
                probe.connect(str(path))
            except (ConnectionRefusedError, FileNotFoundError):
                path.unlink(missing_ok=True)  # left by a sim that died
            else:
                raise ChannelError(f"{path} is held by another sim on ROS_DOMAIN_ID="
                                   f"{domain_id}")
            finally:
                probe.close()
        server = cls(path)
        server.sock.bind(str(path))
        return server

    def poll(self) -> list[tuple[str, str]]:
        """Pending requests as (text, reply address)."""
        out: list[tuple[str, str]] = []
        while True:
            try:
                data, addr = self.sock.recvfrom(MAX_DATAGRAM)
            except BlockingIOError:
                return out
            except OSError:
                return out
            out.append((data.decode(errors="replace").strip(), addr))

    def reply(self, addr: str, text: str) -> None:
        """Answer one request (a client that has gone is ignored)."""
        if not addr:
            return
        data = text.encode()
        if len(data) > MAX_REPLY:
            data = f"error the answer is {len(data)} bytes, over {MAX_REPLY}".encode()
        try:
            self.sock.sendto(data, addr)
        except OSError:
            pass

    def close(self) -> None:
        """Close and remove the socket."""
        self.sock.close()
        self.path.unlink(missing_ok=True)


def request(text: str, domain_id: str | int, timeout: float) -> str | None:
    """Send one request to the sim of ``domain_id``; its answer, or None if no sim listens
    there. ChannelError if it does not answer within ``timeout`` s."""
    path = socket_path(domain_id)
    if not path.exists():
        return None
    d = runtime_dir(create=False)
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    own = d / f"client-{os.getpid()}-{time.monotonic_ns()}.sock"
    try:
        sock.bind(str(own))
        try:
            sock.sendto(text.encode(), str(path))
        except (ConnectionRefusedError, FileNotFoundError):
            return None  # a stale socket: no sim there
        sock.settimeout(timeout)
        try:
            data = sock.recv(MAX_REPLY)
        except TimeoutError as err:
            raise ChannelError(f"the sim on ROS_DOMAIN_ID={domain_id} did not answer within "
                               f"{timeout:g} s") from err
        return data.decode(errors="replace")
    finally:
        sock.close()
        own.unlink(missing_ok=True)


__all__ = ["ChannelError", "SwitchServer", "request", "runtime_dir", "socket_path"]
