"""`StatusTexts`: what an autopilot said (its STATUSTEXTs), kept for the errors and reports that quote it.

Both MAVLink backends keep them the same way (`flight.mavsdk.link.TelemetryCache` for PX4,
`flight.ardupilot.state.ArduPilotState` for ArduPilot): the newest hundred, a count of every text
received, and "what was said since" a count taken earlier (a failsafe sends several texts, and the
one that says why is rarely the last).
"""

from __future__ import annotations

import threading
from collections import deque

KEEP = 100


class StatusTexts:
    """The newest `KEEP` texts an autopilot sent, each as "SEVERITY: text"; thread-safe."""

    def __init__(self, keep: int = KEEP) -> None:
        self._texts: deque[str] = deque(maxlen=keep)
        self._received = 0
        self._lock = threading.Lock()

    def add(self, text: str) -> None:
        with self._lock:
            self._texts.append(text)
            self._received += 1

    @property
    def received(self) -> int:
        """Every text received so far (more than are kept, once `keep` is passed)."""
        with self._lock:
            return self._received

    def all(self) -> list[str]:
        with self._lock:
            return list(self._texts)

    def last(self) -> str:
        with self._lock:
            return self._texts[-1] if self._texts else ""

    def since(self, count: int) -> str:
        """The texts after the first `count` received, "; "-joined (as many as are still kept)."""
        with self._lock:
            new = min(self._received - count, len(self._texts))
            return "; ".join(list(self._texts)[len(self._texts) - new :]) if new > 0 else ""
