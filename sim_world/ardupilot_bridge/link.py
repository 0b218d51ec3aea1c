"""The simulator's end of ArduPilot's JSON interface: a UDP port on loopback that ArduPilot sends to.

ArduPilot (`--model JSON:127.0.0.1`, instance N) sends every servo packet to 127.0.0.1:9002+10N and
reads the reply on the socket it sent from, so the server answers each packet to its sender. The
port is bound at construction (a port in use is an error naming it, before ArduPilot starts), on
127.0.0.1 only. Datagrams that are not servo packets are counted and dropped.
"""

from __future__ import annotations

import contextlib
import errno
import logging
import socket
import time

from drone_inspect_core.ports import ARDUPILOT_JSON_UDP
from sim_world.ardupilot_bridge.protocol import ServoPacket, ServoPacketError

log = logging.getLogger(__name__)


class PhysicsLinkError(OSError):
    """The physics port could not be opened."""


class ArduPilotSilentError(ConnectionError):
    """ArduPilot stopped sending servo packets (it exited, was killed, or hangs)."""


class JsonPhysicsServer:
    """One ArduPilot's physics link; `close()` or a context manager."""

    def __init__(self, host: str = "127.0.0.1", port: int = ARDUPILOT_JSON_UDP) -> None:
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._sock.bind((host, port))
        except OSError as exc:
            self._sock.close()
            hint = (
                " (another ArduPilot bridge or simulator is running there?)"
                if exc.errno == errno.EADDRINUSE
                else ""
            )
            raise PhysicsLinkError(
                exc.errno, f"cannot listen on UDP {host}:{port} for ArduPilot: {exc.strerror}{hint}"
            ) from exc
        self.address = self._sock.getsockname()
        self.peer: tuple[str, int] | None = None
        self.packets_in = 0
        self.bad_packets = 0

    def receive(self, timeout_s: float) -> ServoPacket | None:
        """The next servo packet that arrives within `timeout_s` (None if none); datagrams that are none
        are counted and dropped. (In lockstep there is never more than one packet queued: ArduPilot waits
        for each answer, so no older one is left to drop.)"""
        sock = self._sock
        deadline = time.monotonic() + timeout_s
        while True:
            sock.settimeout(max(0.0, deadline - time.monotonic()))
            try:
                data, peer = sock.recvfrom(512)
            except (TimeoutError, BlockingIOError):
                return None
            try:
                packet = ServoPacket.parse(data)
            except ServoPacketError as exc:
                self.bad_packets += 1
                log.debug("dropped a datagram from %s:%d: %s", *peer, exc)
                continue
            if self.peer != peer:
                log.info("ArduPilot's physics frames come from %s:%d", *peer)
                self.peer = peer
            self.packets_in += 1
            return packet

    def reply(self, data: bytes) -> None:
        """Send the state to ArduPilot (to the sender of the last servo packet)."""
        if self.peer is not None:
            self._sock.sendto(data, self.peer)

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self._sock.close()

    def __enter__(self) -> JsonPhysicsServer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
