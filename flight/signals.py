"""Stop signals handled like Ctrl-C: SIGTERM and SIGHUP end a flight the way SIGINT does.

A supervisor (`timeout`, systemd, a CI runner, a closed terminal) stops a program with
SIGTERM or SIGHUP, not Ctrl-C. Under `stop_signals_as_interrupt()` all three raise
`StopRequested` (a `KeyboardInterrupt`) in the main thread, so every `flight_guard`
holds, lands and disarms, and every report is finished. Once a stop has begun, later
signals are logged and ignored: a second Ctrl-C must not abort the landing it started
(SIGKILL still ends the process at once).
"""

from __future__ import annotations

import logging
import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType

log = logging.getLogger(__name__)

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


class StopRequested(KeyboardInterrupt):
    """A stop signal arrived (SIGINT, SIGTERM or SIGHUP); `signal_name` says which, `exit_code` is the
    shell's code for a process that signal ended (128 + its number: 130, 143, 129)."""

    def __init__(self, signal_name: str) -> None:
        self.signal_name = signal_name
        self.exit_code = 128 + int(signal.Signals[signal_name])
        super().__init__(signal_name)

    def __str__(self) -> str:
        return f"stopped by {self.signal_name}"


@contextmanager
def stop_signals_as_interrupt() -> Iterator[None]:
    """Within the block (main thread only), SIGINT/SIGTERM/SIGHUP raise `StopRequested` once."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    stopping = False

    def handler(signum: int, _frame: FrameType | None) -> None:
        nonlocal stopping
        name = signal.Signals(signum).name
        if stopping:
            log.warning("%s: already stopping (holding, landing, writing the report)", name)
            return
        stopping = True
        raise StopRequested(name)

    previous = {signum: signal.signal(signum, handler) for signum in STOP_SIGNALS}
    try:
        yield
    finally:
        for signum, old in previous.items():
            signal.signal(signum, old)
