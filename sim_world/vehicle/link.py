"""The vehicle's UDP MAVLink 2 endpoint, PX4 SITL style.

PX4 SITL's offboard link binds a local port (14580 + instance) and sends to
127.0.0.1:14540 + instance, where MAVSDK or another offboard API listens. Replies
(acks, parameter values) go to whoever asked. Telemetry goes to the configured remote
and, where `adopt_client` allows (a vehicle served on its own, for a client that
connects out: pymavlink `udpout:`), to the first other peer that speaks MAVLink to
it, locked: a later sender never becomes a destination, so a stranger cannot take
over the stream. A vehicle started for a mission adopts nobody: its remote is the
controller.
"""

from __future__ import annotations

import errno
import logging
import socket
from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink

log = logging.getLogger(__name__)

Address = tuple[str, int]


class LinkError(OSError):
    """The UDP endpoint could not be opened (port in use, bad address)."""


@dataclass
class LinkStats:
    sent: int = 0
    received: int = 0
    bad: int = 0
    send_errors: int = 0


class UdpMavlinkLink:
    """A non-blocking UDP socket that sends and receives MAVLink 2 messages."""

    def __init__(
        self,
        bind_host: str,
        local_port: int,
        remote: Address,
        sysid: int,
        compid: int,
        adopt_client: bool = True,
    ):
        self.remote = remote
        self.stats = LinkStats()
        self.adopt_client = adopt_client
        self.client: Address | None = None
        """The one peer besides `remote` that gets telemetry (the first to speak MAVLink), or None."""
        self._mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._sock.bind((bind_host, local_port))
        except OSError as exc:
            self._sock.close()
            raise LinkError(
                exc.errno, f"cannot bind MAVLink UDP {bind_host}:{local_port}: {exc.strerror}"
            ) from exc
        self._sock.setblocking(False)
        self.local_address: Address = self._sock.getsockname()
        log.info("MAVLink UDP on %s:%d, sending to %s:%d", *self.local_address, *remote)

    def fileno(self) -> int:
        return self._sock.fileno()

    def receive(self) -> list[tuple[mavlink.MAVLink_message, Address]]:
        """All messages waiting in the socket, with their sender."""
        out: list[tuple[mavlink.MAVLink_message, Address]] = []
        while True:
            try:
                data, addr = self._sock.recvfrom(65535)
            except (BlockingIOError, InterruptedError):
                return out
            except ConnectionRefusedError:
                continue  # an ICMP "port unreachable" from an earlier send: nobody listening yet
            # A datagram holds whole frames: parse each on its own, so bytes left over from a bad
            # datagram can never swallow the next good one (a fresh parser costs ~2 µs).
            parser = mavlink.MAVLink(None)
            parser.robust_parsing = True
            valid = False
            try:
                messages = parser.parse_buffer(data) or []
            except Exception:  # a parser that chokes on hostile bytes: nothing usable in them
                self.stats.bad += 1
                continue
            for msg in messages:
                if isinstance(msg, (mavlink.MAVLink_bad_data, mavlink.MAVLink_unknown)):
                    self.stats.bad += 1  # (an unknown id cannot be CRC-checked: random bytes pass as one)
                    continue
                self.stats.received += 1
                out.append((msg, addr))
                valid = True
            if valid and self.adopt_client and self.client is None and addr != self.remote:
                self.client = addr  # only a peer that speaks MAVLink, and only the first
                log.info("MAVLink client at %s:%d gets telemetry too", *addr)

    def destinations(self) -> list[Address]:
        return [self.remote] if self.client is None else [self.remote, self.client]

    @property
    def mav(self) -> mavlink.MAVLink:
        """The sender identity (system, component, sequence) replies are packed with."""
        return self._mav

    def send(self, msg: mavlink.MAVLink_message, to: Address | None = None) -> None:
        """Send to one address, or to every destination when `to` is None."""
        buf = msg.pack(self._mav)
        self._mav.seq = (self._mav.seq + 1) % 256
        self.send_bytes(buf, to)

    def send_bytes(self, buf: bytes, to: Address | None = None) -> None:
        """Send packed bytes to one address, or to every destination when `to` is None."""
        for addr in [to] if to is not None else self.destinations():
            try:
                self._sock.sendto(buf, addr)
                self.stats.sent += 1
            except OSError as exc:
                # Loopback with nobody listening, or a full buffer: telemetry is best effort, like PX4's.
                self.stats.send_errors += 1
                if exc.errno not in (errno.ECONNREFUSED, errno.EAGAIN, errno.ENOBUFS):
                    log.warning("MAVLink send to %s:%d failed: %s", *addr, exc)

    def close(self) -> None:
        self._sock.close()
