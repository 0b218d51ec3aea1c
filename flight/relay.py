"""`MavlinkRelay`: the one UDP relay between a MAVLink vehicle and its client.

Put in the path of a link (vehicle → `listen_port` → relay → `client_port`, where
MAVSDK listens on `udpin://127.0.0.1:<client_port>`, and the client's replies back to
the vehicle's address), it can:

- record a **.tlog** of both directions (`tlog_path`): MAVSDK cannot write telemetry
  logs, so every MAVLink flight's log is written here. The format is the one
  QGroundControl, Mission Planner and pymavlink's `mavutil.mavlink_connection("x.tlog")`
  read: each message preceded by its time as a big-endian uint64 of microseconds since
  the Unix epoch. What is logged is what crossed (after any injected fault): every whole frame
  of a message ArduPilot's dialect knows (it holds every common one), found by its header and
  CRC (`drone_inspect_core.mavlink_frames`), as the bytes that crossed;
- inject a **bad link** (`faults`, `flight.link_faults`): loss, latency, jitter,
  duplication and reordering, both ways;
- **meter** what reaches the vehicle (`message_times_s`: setpoints per second as the
  vehicle sees them) and **cut** the uplink (`drop_uplink`: the controller's stream
  stops, telemetry still flows) or the downlink (`drop_downlink`: telemetry stops, commands
  still reach the vehicle): the flight benchmark and the backend tests use these.

The relay knows its vehicle: it locks onto the address of the first datagram that holds an
autopilot's HEARTBEAT (CRC-checked; of `vehicle_system_id` when the run knows the id, as it does
for every vehicle it starts) and from then on forwards only that address's datagrams; every
other sender on the vehicle side is dropped and counted (`foreign_datagrams`), so a stranger can
neither feed the client telemetry nor receive its commands. On the client side only the client's
own port (`client_port` on loopback, where MAVSDK listens and sends from) is heard.

With a signing key (`signing_key`: MAVLink 2 message signing, `drone_inspect_core.signing`) the relay
signs for a client that cannot: MAVSDK 4's C API has no signing, so every message from the client is
re-packed signed (its sender and sequence kept) before it goes to the vehicle, and only messages the
vehicle signed with the key, fresh, reach the client; unsigned, wrongly signed or replayed ones are
dropped and counted (`unsigned_dropped`), the vehicle's identifying heartbeat included. The .tlog
holds the signed frames, as they crossed the vehicle's link.

Recording never costs the link: a .tlog write that fails (a full disk; a removed folder, checked each
second, as writes into one fail silently) stops the recording, says so once (`recording_error`), cuts
the file back to its last whole message and renames it `*.incomplete.tlog`, and the relay goes on
relaying. A send that fails is counted and
dropped; nothing but `close()` ends the relay.
Only UDP links can be relayed; a serial link's log is not recorded.
"""

from __future__ import annotations

import contextlib
import errno
import logging
import os
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

from drone_inspect_core import mavlink_frames
from drone_inspect_core.files import still_there
from drone_inspect_core.ports import free_port
from drone_inspect_core.signing import FrameSigner, FrameVerifier, SigningKey
from flight.errors import ConnectionUrlError
from flight.link_faults import FaultyDelivery, LinkFaults
from flight.urls import udpin_address

log = logging.getLogger(__name__)

SET_POSITION_TARGET_LOCAL_NED = 84
INCOMPLETE_SUFFIX = ".incomplete.tlog"
"""What a .tlog whose recording stopped early is renamed to end with (`flight.incomplete.tlog`)."""
_MAX_DATAGRAM = 65535
_DRAIN_MAX = 64  # datagrams read from one side per wakeup
_POLL_S = 0.05
_FILE_CHECK_S = 1.0  # how often the .tlog is checked to still be where it was written


def parse_datagram(data: bytes) -> list[mavlink.MAVLink_message]:
    """The whole, known messages of one datagram (a datagram holds whole frames: parsed on its own)."""
    parser = mavlink.MAVLink(None)  # ~2 µs: leftovers of a bad datagram never swallow the next
    parser.robust_parsing = True
    try:
        messages = parser.parse_buffer(data) or []
    except Exception:  # a parser that chokes: nothing we know in it
        return []
    return [m for m in messages if not isinstance(m, (mavlink.MAVLink_bad_data, mavlink.MAVLink_unknown))]


def vehicle_heartbeat_from(messages: list[mavlink.MAVLink_message], system_id: int | None) -> int | None:
    """The system id of an autopilot's HEARTBEAT among `messages` (of `system_id`, when given), else None.

    A ground station's or a peripheral's heartbeat (type GCS, autopilot INVALID) never counts."""
    for message in messages:
        if message.get_msgId() != mavlink.MAVLINK_MSG_ID_HEARTBEAT:
            continue
        if message.type == mavlink.MAV_TYPE_GCS or message.autopilot == mavlink.MAV_AUTOPILOT_INVALID:
            continue
        if system_id is None or message.get_srcSystem() == system_id:
            return message.get_srcSystem()
    return None


class MavlinkRelay:
    """Relay `vehicle → listen_port → client_port` and back; bound and running once constructed.

    `listen_host`: the address to listen on for the vehicle (the host its URL names; loopback by
    default). `vehicle_system_id`: lock onto this system's heartbeat only (None: the first autopilot).
    """

    def __init__(
        self,
        listen_port: int,
        client_port: int,
        tlog_path: str | Path | None = None,
        listen_host: str = "127.0.0.1",
        faults: LinkFaults | None = None,
        vehicle_system_id: int | None = None,
        signing_key: SigningKey | None = None,
    ) -> None:
        self.listen_port = listen_port
        self.client_port = client_port
        self.path = None if tlog_path is None else Path(tlog_path)
        self.client_host = "127.0.0.1"  # the client (MAVSDK) runs on this machine
        self.drop_uplink = False
        self.drop_downlink = False
        self.uplink_counts: Counter[int] = Counter()
        self.messages_logged = 0
        self.vehicle_system_id = vehicle_system_id
        self.vehicle_address: tuple[str, int] | None = None
        self.foreign_datagrams = 0
        """Datagrams dropped because they came from neither the vehicle nor the client."""
        self.unidentified_datagrams = 0
        """Datagrams dropped before the vehicle's heartbeat identified it (PX4 sends others first)."""
        self.send_errors = 0
        self.signed = signing_key is not None
        self.unsigned_dropped = 0
        """Messages from the vehicle side dropped for a missing, wrong or replayed signature."""
        self._signer = None if signing_key is None else FrameSigner(signing_key)
        self._verifier = None if signing_key is None else FrameVerifier(signing_key)
        self.recording_error: str | None = None
        """Why the .tlog stopped early (None while it records, or when it finished whole)."""
        self.faults = FaultyDelivery(faults) if faults is not None and faults.active else None
        """A bad link on purpose: every datagram, both ways, goes through it."""
        self._uplink_times: dict[int, list[float]] = {}
        self._strangers_seen: set[tuple[str, int]] = set()
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
        self.client_side_address = self._client_sock.getsockname()
        """Where the client's datagrams arrive (the relay sends to the client from here too)."""
        self._file: BinaryIO | None = None
        self._logged_bytes = 0
        self._next_check_s = 0.0
        self._file_lock = threading.Lock()  # the relay thread writes, `record_to` swaps the file
        if self.path is not None:
            try:
                self._file = _new_log(self.path)
            except OSError:
                self._vehicle_sock.close()
                self._client_sock.close()
                raise
        self._thread = threading.Thread(target=self._run, name="mavlink-relay", daemon=True)
        self._thread.start()
        log.info(
            "MAVLink relay: udp %s:%d <-> %d%s",
            listen_host,
            listen_port,
            client_port,
            f", log {self.path}" if self.path else "",
        )

    def record_to(self, tlog_path: str | Path) -> None:
        """Finish the current .tlog and record what crosses from now on in `tlog_path` (new), as a fresh
        recording: a relay kept between missions gives each its own log. `OSError` if it cannot start."""
        new_file = _new_log(Path(tlog_path))
        with self._file_lock:
            old, self._file = self._file, new_file
            self.path, self.recording_error = Path(tlog_path), None
            self._logged_bytes = self.messages_logged = 0
            self._next_check_s = 0.0
        if old is not None:
            with contextlib.suppress(OSError):
                old.close()

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
                try:
                    ready = selector.select(timeout)
                except OSError as exc:  # the sockets were closed under us: close() is under way
                    if not self._stop.is_set():
                        log.error("MAVLink relay: select failed: %s", exc)
                    return
                for key, _ in ready:
                    self._receive(key.data)
                if self.faults is not None:
                    for side, data in self.faults.due(time.monotonic()):
                        self._send(side, data)
        finally:
            selector.close()

    def _receive(self, side: str) -> None:
        """The datagrams waiting on `side`'s socket, up to `_DRAIN_MAX` (a burst costs one wakeup)."""
        sock = self._vehicle_sock if side == "vehicle" else self._client_sock
        for _ in range(_DRAIN_MAX):
            try:
                data, address = sock.recvfrom(_MAX_DATAGRAM, socket.MSG_DONTWAIT)
            except OSError:  # none left, an ICMP error from an earlier send, or a socket being closed
                return
            self._relay(side, data, address)

    def _relay(self, side: str, data: bytes, address: tuple[str, int]) -> None:
        if side == "vehicle" and self.vehicle_address is not None and address != self.vehicle_address:
            self._stranger(address)
            return
        if side == "client" and address != (self.client_host, self.client_port):
            self._stranger(address)
            return
        if (side == "client" and self.drop_uplink) or (side == "vehicle" and self.drop_downlink):
            return
        if self._signer is not None:
            data = self._signed(data) if side == "client" else self._verified(data)
            if not data:
                return
        if side == "vehicle" and self.vehicle_address is None and not self._identify_vehicle(data, address):
            self.unidentified_datagrams += 1  # the vehicle's own, often, before its first heartbeat: not said
            return
        if self.faults is not None:
            self.faults.submit(time.monotonic(), (side, data))
        else:
            self._send(side, data)

    def _signed(self, data: bytes) -> bytes:
        """The client's messages in `data`, each re-packed signed with the key."""
        assert self._signer is not None
        out = []
        for message in parse_datagram(data):
            try:
                out.append(self._signer.sign(message))
            except Exception as exc:  # a message pymavlink cannot pack again: not sent unsigned either
                log.warning("MAVLink relay: could not sign %s from the client: %r", message.get_type(), exc)
        return b"".join(out)

    def _verified(self, data: bytes) -> bytes:
        """The frames of `data` signed with the key and fresh; the others are counted and dropped."""
        assert self._verifier is not None
        out = []
        for message in parse_datagram(data):
            frame = bytes(message.get_msgbuf())
            if self._verifier.verify(frame):
                out.append(frame)
            else:
                self.unsigned_dropped += 1
                if self.unsigned_dropped == 1:
                    log.warning(
                        "MAVLink relay: dropping %s: not signed with the link's key", message.get_type()
                    )
        return b"".join(out)

    def _identify_vehicle(self, data: bytes, address: tuple[str, int]) -> bool:
        """Lock onto `address` if `data` holds the vehicle's heartbeat; True if it did."""
        system_id = vehicle_heartbeat_from(parse_datagram(data), self.vehicle_system_id)
        if system_id is None:
            return False
        self.vehicle_address, self.vehicle_system_id = address, system_id
        log.info("MAVLink relay: vehicle is system %d at %s:%d", system_id, *address)
        return True

    def _stranger(self, address: tuple[str, int]) -> None:
        self.foreign_datagrams += 1
        if address not in self._strangers_seen and len(self._strangers_seen) < 64:
            self._strangers_seen.add(address)
            log.warning(
                "MAVLink relay: ignoring datagrams from %s:%d (not this link's vehicle or client)", *address
            )

    def _send(self, side: str, data: bytes) -> None:
        """Forward one datagram; meter and log what crossed. A failed send is counted, never raised."""
        try:
            if side == "vehicle":
                self._client_sock.sendto(data, (self.client_host, self.client_port))
            elif self.vehicle_address is not None:
                self._vehicle_sock.sendto(data, self.vehicle_address)
            else:
                return  # nothing heard from the vehicle yet: nowhere to send
        except OSError as exc:
            self.send_errors += 1
            if self.send_errors == 1:
                log.warning(
                    "MAVLink relay: a %s-bound send failed: %s",
                    "client" if side == "vehicle" else "vehicle",
                    exc,
                )
            return
        if side == "vehicle" and self._file is None:
            return
        frames = mavlink_frames.scan(data, more_to_come=False)[0]  # whole, CRC-checked, of known messages
        if side == "client":
            now = time.monotonic()
            with self._lock:
                for frame in frames:
                    self.uplink_counts[frame.msg_id] += 1
                    self._uplink_times.setdefault(frame.msg_id, []).append(now)
        if self._file is not None and frames:
            with self._file_lock:
                if self._file is not None:
                    self._record([data[f.start : f.end] for f in frames])

    def _record(self, frames: list[bytes]) -> None:
        """Append `frames` (one datagram's) to the .tlog in one write; on a failed write, stop recording
        (once) and keep relaying."""
        assert self._file is not None
        now = time.monotonic()
        if now >= self._next_check_s and self.path is not None:  # a removed folder gives no write error
            self._next_check_s = now + _FILE_CHECK_S
            if not still_there(self._file, self.path):
                self._stop_recording(OSError(errno.ENOENT, "the file or its folder was removed"))
                return
        stamp = struct.pack(">Q", int(time.time() * 1e6))
        records = [stamp + frame for frame in frames]
        block = b"".join(records)
        try:
            written = self._file.write(block)
            if written != len(block):
                whole = 0  # the records that made it whole stay; `_stop_recording` cuts the rest
                for record in records:
                    if written < len(record):
                        break
                    written -= len(record)
                    self._logged_bytes += len(record)
                    self.messages_logged += 1
                    whole += 1
                short = f"{os.strerror(errno.ENOSPC)} ({whole} of {len(records)} messages written whole)"
                raise OSError(errno.ENOSPC, short)
            self._logged_bytes += len(block)
            self.messages_logged += len(records)
        except OSError as exc:
            self._stop_recording(exc)

    def _stop_recording(self, exc: OSError) -> None:
        """Cut the log back to its last whole message, close it, and name it incomplete."""
        file, self._file = self._file, None
        self.recording_error = f"the .tlog stopped after {self.messages_logged} messages: {exc}"
        log.error("MAVLink relay: %s; the flight goes on without it", self.recording_error)
        if file is None or self.path is None:
            return
        with contextlib.suppress(OSError):
            file.truncate(self._logged_bytes)
        with contextlib.suppress(OSError):
            file.close()
        incomplete = self.path.with_name(self.path.stem + INCOMPLETE_SUFFIX)
        try:
            os.replace(self.path, incomplete)
            self.path = incomplete
        except OSError as rename_error:
            log.error(
                "MAVLink relay: could not rename %s to %s: %s", self.path, incomplete.name, rename_error
            )

    # ----------------------------------------------------------------- lifecycle
    def close(self) -> None:
        """Stop relaying and close the log (idempotent)."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)
        for sock in (self._vehicle_sock, self._client_sock):
            sock.close()
        with self._file_lock:
            if self._file is not None:
                try:
                    self._file.close()
                    self._file = None
                except OSError as exc:  # the last bytes could not reach the disk
                    self._stop_recording(exc)

    def __enter__(self) -> MavlinkRelay:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()


def _new_log(path: Path) -> BinaryIO:
    """A new .tlog at `path`, never over an earlier one; `OSError` naming it."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        return path.open("xb", buffering=0)
    except OSError as exc:
        raise OSError(f"MAVLink relay: cannot start the log {path}: {exc}") from exc


def relay_in_front(
    url: str,
    tlog_path: str | Path | None = None,
    faults: LinkFaults | None = None,
    signing_key: SigningKey | None = None,
) -> tuple[MavlinkRelay | None, str]:
    """A relay taking a `udpin://HOST:PORT` vehicle link, and the loopback URL MAVSDK listens on behind it
    (a free port); for any other link (None, `url`): flown directly, without a .tlog.

    With `signing_key` the link is signed, which only the relay can do for MAVSDK: a link that cannot
    be relayed (serial, TCP, udpout) is refused with `ConnectionUrlError` rather than flown unsigned.
    """
    address = udpin_address(url)
    if address is None:
        if signing_key is not None:
            raise ConnectionUrlError(
                url,
                "MAVLink signing needs a udpin:// link: the relay in front of MAVSDK signs (MAVSDK "
                "cannot), and only UDP is relayed",
            )
        return None, url
    host, port = address
    client_port = free_port("udp")
    relay = MavlinkRelay(port, client_port, tlog_path, host, faults, signing_key=signing_key)
    return relay, f"udpin://127.0.0.1:{client_port}"
