"""Byte transports for a pymavlink client, opened from the same connection URLs MAVSDK takes.

`flight.urls.validate_connection_url` checks a URL (`udpin://0.0.0.0:14550`, `udpout://10.0.0.2:14550`,
`tcpout://127.0.0.1:5760`, `serial:///dev/ttyACM0:57600`); `open_transport` opens it:

- `udpin`: bind the address and port; datagrams go back to whoever sent the last one (the vehicle);
- `udpout`: send to the address and port from an ephemeral port, read the replies there;
- `tcpout` (and the deprecated `tcp`): connect to the address and port;
- `serial`: the device at the baud rate, through pyserial (an optional dependency: a clear error
  without it).

A transport only moves bytes (`send`, `receive(timeout_s)`, `close`); MAVLink framing and signing are
the link's (`flight.pymavlink_link`). `tcpin` (wait for the vehicle to dial in) is refused: a flight
controller does not dial a ground station.
"""

from __future__ import annotations

import contextlib
import re
import select
import socket
from typing import Any, Protocol

from flight.errors import ConnectionUrlError, VehicleConnectionError
from flight.urls import validate_connection_url

_MAX_DATAGRAM = 65535


class Transport(Protocol):
    description: str

    def send(self, data: bytes) -> None: ...

    def receive(self, timeout_s: float) -> bytes: ...

    def close(self) -> None: ...


class UdpTransport:
    """A UDP socket: bound (`udpin`, replies to the last sender) or aimed at a peer (`udpout`)."""

    def __init__(self, host: str, port: int, listen: bool) -> None:
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.peer: tuple[str, int] | None = None
        try:
            if listen:
                self._sock.bind((host, port))
            else:
                self.peer = (host, port)
                self._sock.bind(("0.0.0.0" if host not in ("127.0.0.1", "localhost") else "127.0.0.1", 0))
        except OSError as exc:
            self._sock.close()
            raise VehicleConnectionError(
                "connect()", "BIND_ERROR", f"cannot open udp {host}:{port}: {exc.strerror}"
            ) from exc
        self._listen = listen
        self.description = f"udp{'in' if listen else 'out'} {host}:{port}"

    def send(self, data: bytes) -> None:
        if self.peer is not None:
            with contextlib.suppress(OSError):  # a vehicle gone away: the link monitor tells, not a send
                self._sock.sendto(data, self.peer)

    def receive(self, timeout_s: float) -> bytes:
        ready, _, _ = select.select([self._sock], [], [], max(0.0, timeout_s))
        if not ready:
            return b""
        try:
            data, sender = self._sock.recvfrom(_MAX_DATAGRAM)
        except OSError:
            return b""
        if self._listen:
            self.peer = sender
        return data

    def close(self) -> None:
        self._sock.close()


class TcpTransport:
    """A TCP client connection to the vehicle (or to a SITL that listens)."""

    def __init__(self, host: str, port: int, timeout_s: float) -> None:
        try:
            self._sock = socket.create_connection((host, port), timeout=timeout_s)
        except OSError as exc:
            raise VehicleConnectionError(
                "connect()", "CONNECTION_ERROR", f"cannot connect to tcp {host}:{port}: {exc}"
            ) from exc
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._sock.settimeout(1.0)  # a send that cannot complete in a second is dropped
        self.description = f"tcp {host}:{port}"

    def send(self, data: bytes) -> None:
        with contextlib.suppress(OSError):
            self._sock.sendall(data)

    def receive(self, timeout_s: float) -> bytes:
        ready, _, _ = select.select([self._sock], [], [], max(0.0, timeout_s))
        if not ready:
            return b""
        try:
            return self._sock.recv(_MAX_DATAGRAM)
        except OSError:
            return b""

    def close(self) -> None:
        self._sock.close()


class SerialTransport:
    """A serial device through pyserial."""

    def __init__(self, device: str, baud: int) -> None:
        try:
            import serial  # optional: only serial links need it
        except ImportError:
            raise VehicleConnectionError(
                "connect()", "SERIAL_UNAVAILABLE", "serial links need pyserial: pip install pyserial"
            ) from None
        try:
            self._port: Any = serial.Serial(device, baud, timeout=0)
        except (OSError, serial.SerialException) as exc:
            raise VehicleConnectionError("connect()", "CONNECTION_ERROR", f"{device}: {exc}") from exc
        self.description = f"serial {device} at {baud} baud"

    def send(self, data: bytes) -> None:
        self._port.write(data)

    def receive(self, timeout_s: float) -> bytes:
        ready, _, _ = select.select([self._port.fileno()], [], [], max(0.0, timeout_s))
        return self._port.read(self._port.in_waiting or 1) if ready else b""

    def close(self) -> None:
        self._port.close()


def open_transport(url: str, timeout_s: float = 5.0) -> Transport:
    """The transport for a MAVSDK-style connection URL (`ConnectionUrlError` for one that cannot work)."""
    validate_connection_url(url)
    scheme, rest = url.strip().split("://", 1)
    if scheme == "serial":
        device, _, baud = rest.rpartition(":")
        return SerialTransport(device, int(baud))
    host, _, port_text = rest.rpartition(":")
    host, port = host.strip("[]") or "0.0.0.0", int(port_text)
    if scheme in ("udpin", "udp"):
        return UdpTransport(host, port, listen=True)
    if scheme == "udpout":
        return UdpTransport(host, port, listen=False)
    if scheme in ("tcpout", "tcp"):
        return TcpTransport(host, port, timeout_s)
    raise ConnectionUrlError(url, f"{scheme}:// is not supported here: use udpin, udpout, tcpout or serial")


def url_port(url: str) -> int | None:
    """The port of a `udpin://` URL (where a relay can stand in), else None."""
    match = re.fullmatch(r"udpin://[^:/]*:(\d+)", url.strip())
    return int(match.group(1)) if match else None
