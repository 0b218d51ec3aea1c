"""`LinkMonitor`: decides when a vehicle has stopped answering.

Two signals: no telemetry message for `timeout_s` (freshness: PX4 streams attitude
at ~90 Hz, so silence is unambiguous), or MAVSDK's connection state going false (~3 s
after the last heartbeat) while telemetry is also quiet for `quiet_s`. A lossy radio
can lose three heartbeats in a row (at 20 % loss, about once a minute) while attitude
and position keep arriving: that link is alive, and is not declared lost. A simulated autopilot in
lockstep (`clock="vehicle"`: PX4 SITL) sends its heartbeat once a second of *its* time: on a busy machine
it runs at a third of real time or less, MAVSDK's wall-clock heartbeat timeout fires while the vehicle
is merely slow, and its telemetry comes in sparser bursts; there only silence counts
(`connection_state=False`).
Getters in MAVSDK keep returning stale values after a link dies, and commands
that are only enqueued (setpoints) still "succeed", so without this check a
controller would fly blind.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from flight.errors import LinkLostError


class LinkMonitor:
    """Thread-safe: `heard()` and `set_connected()` come from MAVSDK's callback thread."""

    def __init__(
        self,
        timeout_s: float,
        clock: Callable[[], float] = time.monotonic,
        quiet_s: float = 0.5,
        connection_state: bool = True,
        peer_alive: Callable[[], bool] | None = None,
    ) -> None:
        """`peer_alive`: where the vehicle is a simulator this process started, whether its process still
        runs; one that has exited is lost at once, without waiting out the timeout."""
        if not timeout_s > 0:
            raise ValueError(f"link timeout must be > 0, got {timeout_s!r}")
        self.timeout_s = timeout_s
        self.quiet_s = min(quiet_s, timeout_s)
        self._clock = clock
        self._lock = threading.Lock()
        self._last_heard_s = clock()
        self._connected = True
        self._use_connection_state = connection_state
        self._peer_alive = peer_alive

    def heard(self) -> None:
        """A message arrived from the vehicle."""
        now = self._clock()
        with self._lock:
            self._last_heard_s = now
            self._connected = True

    def set_connected(self, connected: bool) -> None:
        """MAVSDK's connection-state change (reported on changes only)."""
        with self._lock:
            self._connected = connected

    def silent_s(self) -> float:
        with self._lock:
            return self._clock() - self._last_heard_s

    def check(self, origin: str) -> None:
        """Raise `LinkLostError` naming `origin` if the vehicle has gone silent."""
        with self._lock:
            silent_s = self._clock() - self._last_heard_s
            connected = self._connected
        if self._peer_alive is not None and not self._peer_alive():
            raise LinkLostError(origin, silent_s, self.timeout_s, "the simulator's process has exited")
        disconnected = not connected and self._use_connection_state
        if silent_s > self.timeout_s or (disconnected and silent_s > self.quiet_s):
            raise LinkLostError(origin, silent_s, self.timeout_s)

    def raise_if_lost(self, origin: str, quiet_s: float = 0.5, poll_s: float = 0.05) -> None:
        """After a command timed out: if the vehicle has been quiet for `quiet_s`, wait for the verdict
        (at most until the link timeout, as silence only grows) and raise `LinkLostError` if the link is
        lost; return as soon as the vehicle is heard again."""
        while self.silent_s() > quiet_s:
            self.check(origin)
            time.sleep(poll_s)
