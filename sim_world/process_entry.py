"""What every simulator process does the same way: stop on signals, stop when its parent is gone, say ready.

A simulator (`sim-vehicle`, the PX4 bridge) runs either from a person's terminal
(`dronectl sim-vehicle`, `dronectl px4-sim`) or as the child of a mission
(`python -m <package> --config FILE.json`, started by `flight.sim_launcher`). Either way:

- SIGINT, SIGTERM and SIGHUP set a stop event: the simulator closes its ports and its
  own children (the render process, PX4) and exits 0 (a stop that hangs for 30 s prints
  every thread's stack and ends the process hard);
- as a child (`watch_parent=True`) it also stops when its parent process is gone,
  however the parent died (SIGKILL included): the parent is polled every 0.5 s, and a
  stop that hangs for 10 s ends the process hard;
- it prints one line `<prefix>{json}` when it is ready, which launchers wait for;
- a launcher's later lines on its stdin (a warm simulator's resets, `drone_inspect_core.launcher_requests`)
  are `LauncherRequests`, which the serving loop takes between its other work.
"""

from __future__ import annotations

import faulthandler
import json
import logging
import os
import queue
import signal
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import asdict, is_dataclass
from pathlib import Path
from typing import Any, TextIO

from drone_inspect_core.launcher_requests import is_pace

log = logging.getLogger(__name__)

PARENT_POLL_S = 0.5
STOP_GRACE_S = 10.0
SIGNAL_STOP_GRACE_S = 30.0
"""A stop asked by a signal may take longer than one on the parent's death: it closes the autopilot (PX4's
own grace is 5 s, then its kill) as well as the simulator."""


def stop_on_signals(name: str) -> threading.Event:
    """An event that SIGINT, SIGTERM and SIGHUP set (call from the main thread).

    No Python code runs for the signal in the main thread: a handler there runs between two of its
    bytecodes, possibly while the main thread holds `stop`'s own lock (inside `stop.wait()`, which the
    serving loops call), and `Event.set()` would then wait for that lock forever (it is not
    re-entrant: `sim-vehicle` once hung so on a SIGTERM). Python's C-level handler writes the signal's
    number to a pipe (`signal.set_wakeup_fd`), and a thread reading it sets the event. That thread
    also bounds the stop: if the process still lives `SIGNAL_STOP_GRACE_S` later, every thread's
    stack goes to stderr and the process ends hard (exit 3)."""
    stop = threading.Event()
    read_fd, write_fd = os.pipe()
    os.set_blocking(write_fd, False)
    for signum in _STOP_SIGNALS:
        signal.signal(signum, _noted)
    signal.set_wakeup_fd(write_fd, warn_on_full_buffer=False)

    def stopping() -> None:
        while not (signums := [s for s in os.read(read_fd, 64) if s in _STOP_SIGNALS]):
            pass
        signal_name = signal.Signals(signums[0]).name
        log.info("%s: %s received, stopping", name, signal_name)
        stop.set()
        time.sleep(SIGNAL_STOP_GRACE_S)
        log.error("%s: still stopping %.0f s after %s: ending hard", name, SIGNAL_STOP_GRACE_S, signal_name)
        faulthandler.dump_traceback(all_threads=True)
        os._exit(3)

    threading.Thread(target=stopping, name="signal-stop", daemon=True).start()
    return stop


_STOP_SIGNALS = frozenset({signal.SIGINT, signal.SIGTERM, signal.SIGHUP})


def _noted(_signum: int, _frame: object) -> None:
    """The Python-level handler of a stop signal: nothing (the wakeup pipe carries it, see
    `stop_on_signals`); it only has to be there for the C-level handler to write to the pipe."""


def watch_parent(stop: threading.Event, name: str) -> None:
    """Set `stop` when our parent is gone (we are re-parented); exit hard if stopping then hangs."""
    parent = os.getppid()

    def watch() -> None:
        while not stop.is_set():
            if os.getppid() != parent:
                log.warning("%s: parent process %d is gone: stopping", name, parent)
                stop.set()
                time.sleep(STOP_GRACE_S)
                os._exit(3)
            time.sleep(PARENT_POLL_S)

    threading.Thread(target=watch, name="parent-watch", daemon=True).start()


def say_ready(out: TextIO, prefix: str, info: Any) -> None:
    """The ready line launchers wait for: `prefix` then the info as one JSON object."""
    data = asdict(info) if is_dataclass(info) and not isinstance(info, type) else info
    out.write(prefix + json.dumps(data) + "\n")
    out.flush()


class LauncherRequests:
    """The launcher's requests after the config, one JSON object a line on `stream` (the child's stdin,
    `drone_inspect_core.launcher_requests`), read by a daemon thread until the stream ends (a launcher
    that asks nothing closes it at once); `take()` hands the serving loop the next one, never blocking.
    Pace requests are not queued: each counts in `paces` (when, `paced_at`, monotonic) and sets `paced`.
    A line that is not a JSON object is said and dropped."""

    def __init__(self, stream: TextIO, name: str) -> None:
        self._queue: queue.Queue[dict[str, Any]] = queue.Queue()
        self._name = name
        self.paces = 0
        self.paced_at = 0.0
        self.paced = threading.Event()
        self._arrived = threading.Event()  # a request was queued since the last `wait`
        threading.Thread(target=self._read, args=(stream,), name="launcher-requests", daemon=True).start()

    def _read(self, stream: TextIO) -> None:
        for line in stream:
            if not line.strip():
                continue
            try:
                request = json.loads(line)
            except ValueError:
                request = None
            if isinstance(request, dict) and is_pace(request):
                self.paced_at = time.monotonic()
                self.paces += 1
                self.paced.set()
            elif isinstance(request, dict):
                self._queue.put(request)
                self._arrived.set()
            else:
                log.error("%s: not a JSON object from the launcher: %.80r", self._name, line)

    def wait(self, timeout_s: float) -> None:
        """Until a request is queued (at once if one is) or `timeout_s` passes."""
        if self._queue.empty():
            self._arrived.wait(timeout_s)
        self._arrived.clear()

    def take(self) -> dict[str, Any] | None:
        try:
            return self._queue.get_nowait()
        except queue.Empty:
            return None


def config_entry_point(
    argv: list[str], module: str, name: str, load: Callable[[dict[str, Any]], Any], serve: Callable[..., int]
) -> int:
    """`python -m <module> --config FILE.json` (or `-`: the JSON on stdin's first line, as launchers pass
    it, the launcher's requests on the lines after it): parse the config with `load`, then
    `serve(config, stdout, watch_parent=True, requests=...)`; 2 on bad usage or a bad config (named),
    else serve's exit code."""
    if len(argv) != 2 or argv[0] != "--config":
        print(f"usage: python -m {module} --config FILE.json|-", file=sys.stderr)
        return 2
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    try:
        text = sys.stdin.readline() if argv[1] == "-" else Path(argv[1]).read_text()
        try:
            data = json.loads(text)
        except ValueError:
            if argv[1] != "-":
                raise
            data = json.loads(text + sys.stdin.read())  # a person's JSON over several lines
        config = load(data)
    except (OSError, ValueError, KeyError, TypeError) as exc:
        print(f"{name}: bad config {argv[1]}: {exc}", file=sys.stderr)
        return 2
    requests = LauncherRequests(sys.stdin, name) if argv[1] == "-" else None
    return serve(config, sys.stdout, watch_parent=True, requests=requests)
