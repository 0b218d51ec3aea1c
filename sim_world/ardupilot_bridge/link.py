"""The simulator's end of ArduPilot's JSON interface: a UDP port on loopback that ArduPilot sends to.

ArduPilot (`--model JSON:127.0.0.1`, instance N) sends every servo packet to 127.0.0.1:9002+10N and
reads the reply on the socket it sent from, so the server answers each packet to its sender. The
port is bound at construction (a port in use is an error naming it, before ArduPilot starts), on
127.0.0.1 only. Datagrams that are not servo packets are counted and dropped. Once told its
ArduPilot's process (`expect_pid`), it takes servo packets only from a socket that process owns
(`sim_world.sitl.peers`): another local program cannot drive the motors, and is never answered.
"""

from __future__ import annotations

import contextlib
import errno
import logging
import socket
import time

from drone_inspect_core.ports import ARDUPILOT_JSON_UDP
from sim_world.ardupilot_bridge.protocol import ServoPacket, ServoPacketError
from sim_world.sitl.peers import udp_sender_owned_by

log = logging.getLogger(__name__)

MAX_REFUSED_SENDERS = 64  # refused senders remembered: said once each, and refused without looking again


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
        self.expect_pid: int | None = None
        """Servo packets are taken only from a socket this process owns (`sim_world.sitl.peers`), once set."""
        self.refused_packets = 0
        """Servo packets dropped because another process than `expect_pid` sent them."""
        self._refused_from: set[tuple[str, int]] = set()

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
                if not self._takes_from(peer):
                    continue
                log.info("ArduPilot's physics frames come from %s:%d", *peer)
                self.peer = peer
            self.packets_in += 1
            return packet

    def _takes_from(self, sender: tuple[str, int]) -> bool:
        """Whether servo packets from `sender` (not the current peer) may fly the drone: with
        `expect_pid`, only that process's; another's is dropped, counted and said once per sender."""
        pid = self.expect_pid
        if pid is None:
            return True
        if sender not in self._refused_from:  # /proc is read once per sender, not once per packet
            if udp_sender_owned_by(sender, pid):
                return True
            if len(self._refused_from) < MAX_REFUSED_SENDERS:
                self._refused_from.add(sender)
                log.warning("dropped servo packets from %s:%d: not ArduPilot (pid %d)", *sender, pid)
        self.refused_packets += 1
        return False

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
