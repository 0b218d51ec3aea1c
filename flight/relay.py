"""`MavlinkRelay`: the one UDP relay between a MAVLink vehicle and its client.

Put in the path of a link (vehicle → `listen_port` → relay → `client_port`, where
MAVSDK listens on `udpin://127.0.0.1:<client_port>`, and the client's replies back to
the vehicle's address), it can:

- record a **.tlog** of both directions (`tlog_path`): MAVSDK cannot write telemetry
  logs, so every MAVLink flight's log is written here. The format is the one
  QGroundControl, Mission Planner and pymavlink's `mavutil.mavlink_connection("x.tlog")`
  read: each message preceded by its time as a big-endian uint64 of microseconds since
  the Unix epoch. What is logged is what crossed (after any injected fault);
- inject a **bad link** (`faults`, `flight.link_faults`): loss, latency, jitter,
  duplication and reordering, both ways;
- **meter** what reaches the vehicle (`message_times_s`: setpoints per second as the
  vehicle sees them) and **cut** the uplink (`drop_uplink`: the controller's stream
  stops, telemetry still flows): the flight benchmark and the backend tests use these.

The vehicle's address is learned from the first datagram that holds real MAVLink (a
frame of a known id, so CRC-checked): a sender of garbage never becomes "the vehicle".
Only UDP links can be relayed; a serial link's log is not recorded.
"""

from __future__ import annotations

import logging
import selectors
import socket
import struct
import threading
import time
from collections import Counter
from pathlib import Path
from types import TracebackType
from typing import BinaryIO

from pymavlink.dialects.v20 import common as mavlink

from flight.link_faults import FaultyDelivery, LinkFaults

log = logging.getLogger(__name__)

SET_POSITION_TARGET_LOCAL_NED = 84
_MAX_DATAGRAM = 65535
_POLL_S = 0.05


def parse_datagram(data: bytes) -> list[mavlink.MAVLink_message]:
    """The whole, known messages of one datagram (a datagram holds whole frames: parsed on its own)."""
    parser = mavlink.MAVLink(None)  # ~2 µs: leftovers of a bad datagram never swallow the next
    parser.robust_parsing = True
    try:
        messages = parser.parse_buffer(data) or []
    except Exception:  # a parser that chokes: nothing we know in it
        return []
    return [m for m in messages if not isinstance(m, (mavlink.MAVLink_bad_data, mavlink.MAVLink_unknown))]


class MavlinkRelay:
    """Relay `vehicle → listen_port → client_port` and back; bound and running once constructed."""

    def __init__(
        self,
        listen_port: int,
        client_port: int,
        tlog_path: str | Path | None = None,
        listen_host: str = "127.0.0.1",
        faults: LinkFaults | None = None,
    ) -> None:
        self.listen_port = listen_port
        self.client_port = client_port
        self.path = None if tlog_path is None else Path(tlog_path)
        self.client_host = "127.0.0.1"  # the client (MAVSDK) runs on this machine
        self.drop_uplink = False
        self.uplink_counts: Counter[int] = Counter()
        self.messages_logged = 0
        self.vehicle_address: tuple[str, int] | None = None
        self.faults = FaultyDelivery(faults) if faults is not None and faults.active else None
        """A bad link on purpose: every datagram, both ways, goes through it."""
        self._uplink_times: dict[int, list[float]] = {}
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._vehicle_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._vehicle_sock.bind((listen_host, listen_port))
        except OSError as exc:
            self._vehicle_sock.close()
            raise OSError(f"MAVLink relay: cannot listen on udp {listen_host}:{listen_port}: {exc}") from exc
        self.listen_address = self._vehicle_sock.getsockname()
        self._client_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._client_sock.bind((self.client_host, 0))
        self._file: BinaryIO | None = None
        if self.path is not None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._file = self.path.open("wb")
        self._thread = threading.Thread(target=self._run, name="mavlink-relay", daemon=True)
        self._thread.start()
        log.info(
            "MAVLink relay: udp %d <-> %d%s",
            listen_port,
            client_port,
            f", log {self.path}" if self.path else "",
        )

    def message_times_s(self, msg_id: int) -> list[float]:
        """Monotonic times at which uplink messages `msg_id` were forwarded to the vehicle."""
        with self._lock:
            return list(self._uplink_times.get(msg_id, []))

    # ------------------------------------------------------------------ relaying
    def _run(self) -> None:
        selector = selectors.DefaultSelector()
        selector.register(self._vehicle_sock, selectors.EVENT_READ, "vehicle")
        selector.register(self._client_sock, selectors.EVENT_READ, "client")
        try:
            while not self._stop.is_set():
                timeout = _POLL_S
                if self.faults is not None and (at := self.faults.next_due_s()) is not None:
                    timeout = min(timeout, max(0.0, at - time.monotonic()))
                for key, _ in selector.select(timeout):
                    self._receive(key.data)
                if self.faults is not None:
                    for side, data in self.faults.due(time.monotonic()):
                        self._send(side, data)
        except OSError as exc:
            if not self._stop.is_set():
                log.error("MAVLink relay stopped: %s", exc)
        finally:
            selector.close()

    def _receive(self, side: str) -> None:
        sock = self._vehicle_sock if side == "vehicle" else self._client_sock
        data, address = sock.recvfrom(_MAX_DATAGRAM)
        if side == "vehicle" and self.vehicle_address != address:
            if not parse_datagram(data):
                return  # not MAVLink: never let it become the vehicle's address
            self.vehicle_address = address
        if side == "client" and self.drop_uplink:
            return
        if self.faults is not None:
            self.faults.submit(time.monotonic(), (side, data))
        else:
            self._send(side, data)

    def _send(self, side: str, data: bytes) -> None:
        """Forward one datagram; meter and log what crossed."""
        if side == "vehicle":
            self._client_sock.sendto(data, (self.client_host, self.client_port))
            messages = parse_datagram(data) if self._file is not None else []
        else:
            if self.vehicle_address is None:
                return  # nothing heard from the vehicle yet: nowhere to send
            self._vehicle_sock.sendto(data, self.vehicle_address)
            messages = parse_datagram(data)
            now = time.monotonic()
            with self._lock:
                for message in messages:
                    msg_id = message.get_msgId()
                    self.uplink_counts[msg_id] += 1
                    self._uplink_times.setdefault(msg_id, []).append(now)
        if self._file is not None:
            stamp = struct.pack(">Q", int(time.time() * 1e6))
            for message in messages:
                self._file.write(stamp + bytes(message.get_msgbuf()))
                self.messages_logged += 1

    # ----------------------------------------------------------------- lifecycle
    def close(self) -> None:
        """Stop relaying and close the log (idempotent)."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)
        for sock in (self._vehicle_sock, self._client_sock):
            sock.close()
        if self._file is not None:
            self._file.close()
            self._file = None

    def __enter__(self) -> MavlinkRelay:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()
