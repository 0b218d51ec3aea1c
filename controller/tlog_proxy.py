"""A UDP relay between a MAVLink vehicle and its client that writes every message to a .tlog.

MAVSDK cannot write telemetry logs, so a MAVLink flight's .tlog is recorded here,
between the two: the vehicle sends to `listen_port` (where a ground station would
listen), the relay forwards each datagram unchanged to the client at `client_port`
(MAVSDK on `udpin://127.0.0.1:<client_port>`) and the client's replies back to the
vehicle's address. Both directions are logged, so the log holds the commands and
setpoints as well as the telemetry.

The .tlog format is the one QGroundControl, Mission Planner and pymavlink's
`mavutil.mavlink_connection("x.tlog")` read: each MAVLink packet preceded by its
arrival time as a big-endian uint64 of microseconds since the Unix epoch.
Only UDP links can be relayed; a serial link's log is not recorded.
"""

from __future__ import annotations

import logging
import selectors
import socket
import struct
import threading
import time
from pathlib import Path
from types import TracebackType

from pymavlink.dialects.v20 import common as mavlink

from flight.link_faults import FaultyDelivery, LinkFaults

log = logging.getLogger(__name__)


_MAX_DATAGRAM = 65535
_POLL_S = 0.05


class MavlinkTlogProxy:
    """Relay `vehicle → 127.0.0.1:listen_port → 127.0.0.1:client_port` and back, logging to `path`."""

    def __init__(
        self,
        listen_port: int,
        client_port: int,
        path: str | Path,
        listen_host: str = "127.0.0.1",
        faults: LinkFaults | None = None,
    ) -> None:
        self.listen_port = listen_port
        self.client_port = client_port
        self.path = Path(path)
        self.listen_host = listen_host  # 0.0.0.0 for a vehicle on another machine
        self.client_host = "127.0.0.1"  # the client (MAVSDK) runs in this process
        self.messages_logged = 0
        self.vehicle_address: tuple[str, int] | None = None
        self._vehicle_sock: socket.socket | None = None
        self._client_sock: socket.socket | None = None
        self._file = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.faults = FaultyDelivery(faults) if faults is not None and faults.active else None
        """A bad link on purpose (`flight.link_faults`): every datagram, both ways, goes through it."""

    def start(self) -> MavlinkTlogProxy:
        """Bind the vehicle-side port (raises OSError naming it if taken) and start relaying."""
        vehicle_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            vehicle_sock.bind((self.listen_host, self.listen_port))
        except OSError as exc:
            vehicle_sock.close()
            raise OSError(
                f"tlog proxy: cannot listen on udp {self.listen_host}:{self.listen_port}: {exc}"
            ) from exc
        client_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        client_sock.bind((self.client_host, 0))
        self._vehicle_sock, self._client_sock = vehicle_sock, client_sock
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = self.path.open("wb")
        self._thread = threading.Thread(target=self._run, name="tlog-proxy", daemon=True)
        self._thread.start()
        log.info("tlog proxy: udp %d <-> %d, logging to %s", self.listen_port, self.client_port, self.path)
        return self

    def _run(self) -> None:
        assert self._vehicle_sock is not None and self._client_sock is not None
        selector = selectors.DefaultSelector()
        selector.register(self._vehicle_sock, selectors.EVENT_READ, "vehicle")
        selector.register(self._client_sock, selectors.EVENT_READ, "client")
        try:
            while not self._stop.is_set():
                timeout = _POLL_S
                if self.faults is not None and (at := self.faults.next_due_s()) is not None:
                    timeout = min(timeout, max(0.0, at - time.monotonic()))
                for key, _ in selector.select(timeout):
                    self._relay(key.data)
                if self.faults is not None:
                    for side, data in self.faults.due(time.monotonic()):
                        self._send(side, data)
        except OSError as exc:
            if not self._stop.is_set():
                log.error("tlog proxy stopped: %s", exc)
        finally:
            selector.close()

    def _relay(self, side: str) -> None:
        assert self._vehicle_sock is not None and self._client_sock is not None
        sock = self._vehicle_sock if side == "vehicle" else self._client_sock
        data, address = sock.recvfrom(_MAX_DATAGRAM)
        if side == "vehicle" and self.vehicle_address != address:
            if not self._speaks_mavlink(data):
                return  # not MAVLink: never let it become the vehicle's address
            self.vehicle_address = address
        if self.faults is not None:
            self.faults.submit(time.monotonic(), (side, data))
        else:
            self._send(side, data)

    def _send(self, side: str, data: bytes) -> None:
        """Forward one datagram and log what crossed (after any injected fault: what the other side got)."""
        assert self._vehicle_sock is not None and self._client_sock is not None
        if side == "vehicle":
            self._client_sock.sendto(data, (self.client_host, self.client_port))
        else:
            if self.vehicle_address is None:
                return  # nothing heard from the vehicle yet: nowhere to send
            self._vehicle_sock.sendto(data, self.vehicle_address)
        self._log(side, data)

    @staticmethod
    def _speaks_mavlink(data: bytes) -> bool:
        """A datagram holding at least one whole MAVLink message of a known id (so CRC-checked)."""
        parser = mavlink.MAVLink(None)
        parser.robust_parsing = True
        try:
            messages = parser.parse_buffer(data) or []
        except Exception:  # a parser that chokes: not MAVLink we know
            return False
        return any(not isinstance(m, (mavlink.MAVLink_bad_data, mavlink.MAVLink_unknown)) for m in messages)

    def _log(self, side: str, data: bytes) -> None:
        stamp = struct.pack(">Q", int(time.time() * 1e6))
        parser = mavlink.MAVLink(None)  # per datagram: leftovers of a bad one never eat the next
        parser.robust_parsing = True
        try:
            messages = parser.parse_buffer(data) or []
        except Exception as exc:  # relayed anyway: a datagram the parser chokes on is left out of the log
            log.warning("tlog proxy: %s datagram not logged (%s: %s)", side, type(exc).__name__, exc)
            return
        assert self._file is not None
        for message in messages:
            if message.get_type() == "BAD_DATA":
                continue
            self._file.write(stamp + bytes(message.get_msgbuf()))
            self.messages_logged += 1

    def close(self) -> None:
        """Stop relaying and close the log (idempotent)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        for sock in (self._vehicle_sock, self._client_sock):
            if sock is not None:
                sock.close()
        self._vehicle_sock = self._client_sock = None
        if self._file is not None:
            self._file.close()
            self._file = None

    def __enter__(self) -> MavlinkTlogProxy:
        return self.start()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()
