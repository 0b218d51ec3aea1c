"""`MavlinkRelay`: a loopback UDP relay between a vehicle and a client, counting and cutting traffic.

Put in the path of a real link (vehicle → relay port → client port), it meters
what actually crosses the wire toward the vehicle (setpoints per second, as the
vehicle sees them) and injects faults a real radio link has: `drop_uplink`
silences everything the client sends (the controller's setpoint stream stops,
telemetry still flows). For the flight benchmark and the backend tests; flying
never needs it.

MAVLink frames are read from their headers only (v2: 0xFD, msgid in bytes 7–9;
v1: 0xFE, msgid in byte 5), so the relay needs no dialect and adds ~0.1 ms.
"""

from __future__ import annotations

import logging
import select
import socket
import threading
import time
from collections import Counter
from types import TracebackType

log = logging.getLogger(__name__)

SET_POSITION_TARGET_LOCAL_NED = 84
_V2, _V1 = 0xFD, 0xFE


def mavlink_message_ids(datagram: bytes) -> list[int]:
    """The message ids of the MAVLink frames in one datagram (stops at the first malformed byte)."""
    ids: list[int] = []
    i = 0
    while i + 8 <= len(datagram):
        magic, length = datagram[i], datagram[i + 1]
        if magic == _V2 and i + 10 <= len(datagram):
            ids.append(int.from_bytes(datagram[i + 7 : i + 10], "little"))
            signed = datagram[i + 2] & 0x01
            i += 12 + length + (13 if signed else 0)
        elif magic == _V1:
            ids.append(datagram[i + 5])
            i += 8 + length
        else:
            break
    return ids


class MavlinkRelay:
    """Listens on `listen_port` (where the vehicle sends); forwards to `client_port` (where MAVSDK listens).

    Replies from the client go back to the vehicle's last address unless `drop_uplink` is set.
    """

    def __init__(self, listen_port: int, client_port: int, host: str = "127.0.0.1") -> None:
        self.drop_uplink = False
        self.uplink_counts: Counter[int] = Counter()
        self.uplink_times_s: dict[int, list[float]] = {}
        self._client = (host, client_port)
        self._vehicle: tuple[str, int] | None = None
        self._lock = threading.Lock()
        self._from_vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._from_vehicle.bind((host, listen_port))
        self._to_client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._to_client.bind((host, 0))
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="mavlink-relay", daemon=True)
        self._thread.start()

    def message_times_s(self, msg_id: int) -> list[float]:
        """Monotonic arrival times of every uplink message `msg_id` forwarded so far."""
        with self._lock:
            return list(self.uplink_times_s.get(msg_id, []))

    def _run(self) -> None:
        sockets = [self._from_vehicle, self._to_client]
        while not self._stop.is_set():
            ready, _, _ = select.select(sockets, [], [], 0.05)
            for sock in ready:
                try:
                    data, sender = sock.recvfrom(65535)
                except OSError:
                    continue
                if sock is self._from_vehicle:
                    self._vehicle = sender
                    self._to_client.sendto(data, self._client)
                elif not self.drop_uplink and self._vehicle is not None:
                    now = time.monotonic()
                    with self._lock:
                        for msg_id in mavlink_message_ids(data):
                            self.uplink_counts[msg_id] += 1
                            self.uplink_times_s.setdefault(msg_id, []).append(now)
                    self._from_vehicle.sendto(data, self._vehicle)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=1.0)
        self._from_vehicle.close()
        self._to_client.close()

    def __enter__(self) -> MavlinkRelay:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()
