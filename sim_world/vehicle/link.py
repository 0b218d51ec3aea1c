"""The vehicle's UDP MAVLink 2 endpoint, PX4 SITL style.

PX4 SITL's offboard link binds a local port (14580 + instance) and sends to
127.0.0.1:14540 + instance, where MAVSDK or another offboard API listens. Replies
(acks, parameter values) go to whoever asked. Telemetry goes to the configured remote
and, where `adopt_client` allows (a vehicle served on its own, for a client that
connects out: pymavlink `udpout:`), to the first other peer that speaks MAVLink to
it, locked: a later sender never becomes a destination, so a stranger cannot take
over the stream. A vehicle started for a mission adopts nobody: its remote is the
controller, and what any other address sends is dropped unread (`LinkStats.foreign`).

With a signing key (MAVLink 2 signing, `drone_inspect_core.signing`) everything the vehicle
sends is signed, and a received message counts only when it is signed with that key and
fresh; an unsigned, wrongly signed or replayed one is dropped (`LinkStats.unsigned`) before
anything reads it, so it can neither command the vehicle nor make it a telemetry peer.
"""

from __future__ import annotations

import errno
import logging
import socket
from collections import Counter
from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink

from drone_inspect_core.signing import FrameVerifier, SigningKey, enable_signing

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
    unsigned: int = 0
    """Messages dropped for a missing, wrong or replayed signature (with a signing key)."""
    foreign: int = 0
    """Datagrams dropped because they came from an address that is not this vehicle's controller."""


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
        signing_key: SigningKey | None = None,
    ):
        self.remote = remote
        self.stats = LinkStats()
        self.adopt_client = adopt_client
        self.client: Address | None = None
        """The one peer besides `remote` that gets telemetry (the first to speak MAVLink), or None."""
        self._mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
        self._verifier = None if signing_key is None else FrameVerifier(signing_key)
        if signing_key is not None:
            enable_signing(self._mav, signing_key)
        self._strangers_seen: set[Address] = set()
        self.senders: Counter[tuple[int, int]] = Counter()
        """Messages accepted per (system, component) that sent them."""
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
            if not self.adopt_client and addr != self.remote:
                self._stranger(addr)  # a mission's vehicle hears its controller only
                continue
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
                if self._verifier is not None and not self._verifier.verify(msg.get_msgbuf()):
                    self.stats.unsigned += 1
                    if self.stats.unsigned == 1:
                        kind = msg.get_type()
                        log.warning("dropping %s from %s:%d: not signed with this run's key", kind, *addr)
                    continue
                self.stats.received += 1
                self.senders[(msg.get_srcSystem(), msg.get_srcComponent())] += 1
                out.append((msg, addr))
                valid = True
            if valid and self.adopt_client and self.client is None and addr != self.remote:
                self.client = addr  # only a peer that speaks MAVLink, and only the first
                log.info("MAVLink client at %s:%d gets telemetry too", *addr)

    def _stranger(self, addr: Address) -> None:
        self.stats.foreign += 1
        if addr not in self._strangers_seen and len(self._strangers_seen) < 64:
            self._strangers_seen.add(addr)
            log.warning("ignoring datagrams from %s:%d: not this vehicle's controller", *addr)

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
