"""A lossy link, on purpose: loss, latency, jitter, duplication and reordering of UDP datagrams.

`FaultyDelivery` sits in a relay between a vehicle and its client (the .tlog relay of
the MAVLink missions) and decides, for each datagram in either direction, whether it
is dropped, when it goes out, and whether it goes out twice. It is what users run to
see how a mission degrades over a bad radio (`faults: {link: ...}` in a mission file,
`--link-loss 0.2 --link-latency-ms 200` on `dronectl benchmark-missions`). Seeded:
the same seed drops the same datagrams.

Model, per datagram and independently per direction: dropped with probability
`loss`; otherwise delivered after `latency_ms` plus a uniform jitter in
[-jitter_ms, +jitter_ms] (never below 0); with probability `reorder` held back one
more `latency_ms + jitter_ms`, so later datagrams overtake it; with probability
`duplicate` delivered a second time, 1 ms later.
"""

from __future__ import annotations

import heapq
import itertools
import random
import threading
from dataclasses import dataclass
from typing import Any

from pydantic import Field

from drone_inspect_core.config_files import StrictModel


class LinkFaults(StrictModel):
    """What a bad link does to each datagram (fractions in [0, 1), times in ms): the mission file's
    `faults.link` section and the relay's setting, one type."""

    loss: float = Field(default=0.0, ge=0.0, lt=1.0)
    latency_ms: float = Field(default=0.0, ge=0.0, le=10_000.0)
    jitter_ms: float = Field(default=0.0, ge=0.0, le=10_000.0)
    duplicate: float = Field(default=0.0, ge=0.0, lt=1.0)
    reorder: float = Field(default=0.0, ge=0.0, lt=1.0)
    seed: int = Field(default=0, ge=0)

    @property
    def active(self) -> bool:
        return any((self.loss, self.latency_ms, self.jitter_ms, self.duplicate, self.reorder))


@dataclass
class FaultCounts:
    datagrams: int = 0
    dropped: int = 0
    duplicated: int = 0
    reordered: int = 0


class FaultyDelivery:
    """Schedules datagrams under `LinkFaults`; thread-safe. `due()` yields what must go out now."""

    def __init__(self, faults: LinkFaults) -> None:
        self.faults = faults
        self.counts = FaultCounts()
        self._rng = random.Random(faults.seed)
        self._queue: list[tuple[float, int, Any]] = []
        self._order = itertools.count()
        self._lock = threading.Lock()

    def submit(self, now_s: float, item: Any) -> None:
        """A datagram (`item`: whatever the relay needs to send it) arrived at `now_s`."""
        f, rng = self.faults, self._rng
        with self._lock:
            self.counts.datagrams += 1
            if f.loss and rng.random() < f.loss:
                self.counts.dropped += 1
                return
            delay_ms = f.latency_ms + (rng.uniform(-f.jitter_ms, f.jitter_ms) if f.jitter_ms else 0.0)
            if f.reorder and rng.random() < f.reorder:
                delay_ms += f.latency_ms + f.jitter_ms + 1.0
                self.counts.reordered += 1
            at = now_s + max(0.0, delay_ms) / 1000.0
            heapq.heappush(self._queue, (at, next(self._order), item))
            if f.duplicate and rng.random() < f.duplicate:
                self.counts.duplicated += 1
                heapq.heappush(self._queue, (at + 0.001, next(self._order), item))

    def due(self, now_s: float) -> list[Any]:
        """Everything whose time has come, in delivery order."""
        out = []
        with self._lock:
            while self._queue and self._queue[0][0] <= now_s:
                out.append(heapq.heappop(self._queue)[2])
        return out

    def next_due_s(self) -> float | None:
        with self._lock:
            return self._queue[0][0] if self._queue else None
