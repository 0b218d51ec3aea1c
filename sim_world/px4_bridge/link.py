"""The simulator's end of PX4's simulator link: a TCP server PX4 connects to as a client.

PX4 (`simulator_mavlink start -c 4560+N`) dials 127.0.0.1:4560+N every 0.5 ms
until something listens, then exchanges MAVLink 2 over the one connection. The
server here binds at construction (so a port already in use is an error naming
the port, before PX4 starts), accepts exactly one client, and reads whole MAVLink
frames from the byte stream.

It takes only its PX4: with `expect_pid` a connection is accepted only when that process
owns the other end (`sim_world.sitl.peers`); any other local program that dials in first is
closed at once and said once, whatever it sends. Once PX4 is connected the listening socket is
closed, so nobody else can even connect.
"""

from __future__ import annotations

import contextlib
import errno
import logging
import select
import socket
import time
from typing import NamedTuple

from drone_inspect_core import mavlink_frames
from drone_inspect_core.ports import PX4_SIMULATOR_TCP
from sim_world.sitl.peers import tcp_connection_owned_by

log = logging.getLogger(__name__)


class LinkFrame(NamedTuple):
    """One whole, CRC-checked frame from PX4: its message id and its payload as sent (MAVLink 2 cuts
    trailing zeros)."""

    msg_id: int
    payload: bytes

    @property
    def name(self) -> str:
        return mavlink_frames.name_of(self.msg_id)


class SimulatorLinkError(OSError):
    """The simulator port could not be opened, or PX4 did not connect in time."""


class Px4DisconnectedError(ConnectionError):
    """PX4 closed the simulator connection (it exited or was killed)."""


class SimulatorServer:
    """TCP server for one PX4 connection; `close()` or a context manager."""

    def __init__(self, host: str = "127.0.0.1", port: int = PX4_SIMULATOR_TCP) -> None:
        self._listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        try:
            self._listener.bind((host, port))
            self._listener.listen(1)
        except OSError as exc:
            self._listener.close()
            hint = (
                " (another simulator or PX4 bridge is running there?)"
                if exc.errno == errno.EADDRINUSE
                else ""
            )
            raise SimulatorLinkError(
                exc.errno, f"cannot listen on TCP {host}:{port} for PX4: {exc.strerror}{hint}"
            ) from exc
        self.address = self._listener.getsockname()
        self._conn: socket.socket | None = None
        self._pending = b""  # bytes of a frame not yet whole
        self.peer: tuple[str, int] | None = None
        self.bytes_in = 0
        self.bytes_out = 0
        self.bad_frames = 0
        self.refused = 0
        """Connections closed at once because another process than PX4 made them."""

    @property
    def connected(self) -> bool:
        return self._conn is not None

    def accept(self, timeout_s: float, expect_pid: int | None = None) -> tuple[str, int]:
        """Wait for PX4 (the process `expect_pid`, when given) to connect; SimulatorLinkError after
        `timeout_s`. Connections from any other process are closed and counted (`refused`)."""
        deadline = time.monotonic() + max(0.0, timeout_s)
        while True:
            ready, _, _ = select.select([self._listener], [], [], max(0.0, deadline - time.monotonic()))
            if not ready:
                where = f"TCP {self.address[0]}:{self.address[1]}"
                raise SimulatorLinkError(
                    errno.ETIMEDOUT, f"PX4 did not connect to {where} within {timeout_s:.0f} s"
                )
            conn, peer = self._listener.accept()
            if expect_pid is None or tcp_connection_owned_by(conn, expect_pid):
                break
            self.refused += 1
            if self.refused == 1:
                log.warning("refused a simulator connection from %s:%d: not PX4 (pid %d)", *peer, expect_pid)
            conn.close()
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        conn.setblocking(False)
        self._conn, self.peer = conn, peer
        self._listener.close()  # one PX4, and nobody after it
        log.info("PX4 connected from %s:%d", *peer)
        return peer

    def send(self, data: bytes, timeout_s: float = 2.0) -> None:
        """Send whole frames; Px4DisconnectedError if PX4 is gone or stops reading for `timeout_s`."""
        conn = self._require()
        view = memoryview(data)
        deadline = time.monotonic() + timeout_s
        while view:
            try:
                sent = conn.send(view)
            except BlockingIOError:
                sent = 0
            except OSError as exc:
                raise Px4DisconnectedError(f"PX4 simulator link: {exc}") from exc
            view = view[sent:]
            self.bytes_out += sent
            if view:
                left = deadline - time.monotonic()
                if left <= 0:
                    raise Px4DisconnectedError(
                        f"PX4 stopped reading the simulator link for {timeout_s:.1f} s"
                    )
                select.select([], [conn], [], left)

    def receive(self, timeout_s: float) -> list[LinkFrame]:
        """The frames that arrive within `timeout_s` (returns as soon as any arrive)."""
        conn = self._require()
        ready, _, _ = select.select([conn], [], [], max(0.0, timeout_s))
        if not ready:
            return []
        frames: list[LinkFrame] = []
        while True:
            try:
                data = conn.recv(65536)
            except BlockingIOError:
                break
            except OSError as exc:
                raise Px4DisconnectedError(f"PX4 simulator link: {exc}") from exc
            if not data:
                raise Px4DisconnectedError("PX4 closed the simulator connection")
            self.bytes_in += len(data)
            frames += self._frames(data)
            if len(data) < 65536:
                break
        return frames

    def _frames(self, data: bytes) -> list[LinkFrame]:
        """The whole frames of known messages in the stream so far (`drone_inspect_core.mavlink_frames`:
        a bad header never swallows the good frames after it); a frame not yet whole waits for the rest."""
        pending = self._pending + data
        frames, used, bad = mavlink_frames.scan(pending)
        self.bad_frames += bad
        self._pending = pending[used:]
        return [LinkFrame(f.msg_id, pending[f.payload_start : f.payload_end]) for f in frames]

    def _require(self) -> socket.socket:
        if self._conn is None:
            raise Px4DisconnectedError("PX4 is not connected")
        return self._conn

    def close(self) -> None:
        for sock in (self._conn, self._listener):
            if sock is not None:
                with contextlib.suppress(OSError):
                    sock.close()
        self._conn = None

    def __enter__(self) -> SimulatorServer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
