"""`SimulatorProcess`: a simulator's own entry point (`python -m <package> --config FILE`) as a child.

The child runs in its own session, so a Ctrl-C in the terminal reaches only the
controller (which lands first and then stops the child); it watches its parent and
stops by itself within a second when the parent dies, however the parent dies. It
prints one line `<prefix>{json}` when it is ready; `start()` waits for that line (or
for the child's exit, reported with the end of its log) and `ready` holds the JSON.
`close()` sends SIGTERM (the child stops its own children and writes its logs), then
SIGKILL to the whole process group if it hangs.

This module imports nothing of the simulator: a real-vehicle run never loads it.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from types import TracebackType
from typing import Any

log = logging.getLogger(__name__)


class SimulatorStartError(RuntimeError):
    """The simulator exited or did not become ready; the message carries the end of its log."""


class SimulatorProcess:
    """One simulator child process; `start()` then `close()`, or a context manager."""

    def __init__(
        self,
        module: str,
        config: dict[str, Any],
        log_path: Path,
        ready_prefix: str,
        start_timeout_s: float = 90.0,
        name: str = "simulator",
    ) -> None:
        self.module, self.config, self.log_path = module, config, Path(log_path)
        self.ready_prefix, self.start_timeout_s, self.name = ready_prefix, start_timeout_s, name
        self.config_path = self.log_path.with_suffix(".json")
        self.ready: dict[str, Any] = {}
        self._process: subprocess.Popen[bytes] | None = None

    def start(self) -> SimulatorProcess:
        self.log_path.parent.mkdir(parents=True, exist_ok=True)
        self.config_path.write_text(json.dumps(self.config, indent=2))
        command = [sys.executable, "-m", self.module, "--config", str(self.config_path)]
        with self.log_path.open("wb") as log_file:
            self._process = subprocess.Popen(
                command,
                stdin=subprocess.DEVNULL,
                stdout=log_file,
                stderr=subprocess.STDOUT,
                start_new_session=True,
            )
        try:
            self._wait_ready()
        except BaseException:
            self.close()
            raise
        log.info("%s ready (pid %d): %s", self.name, self._process.pid, self.ready)
        return self

    def _wait_ready(self) -> None:
        assert self._process is not None
        deadline = time.monotonic() + self.start_timeout_s
        while True:
            for line in self.output().splitlines():
                if line.startswith(self.ready_prefix):
                    self.ready = json.loads(line[len(self.ready_prefix) :])
                    return
            if self._process.poll() is not None:
                raise SimulatorStartError(
                    f"{self.name} exited with {self._process.returncode} before it was ready; "
                    f"{self.log_path} ends with:\n{self.output()[-2000:]}"
                )
            if time.monotonic() > deadline:
                raise SimulatorStartError(
                    f"{self.name} not ready within {self.start_timeout_s:.0f} s; "
                    f"{self.log_path} ends with:\n{self.output()[-2000:]}"
                )
            time.sleep(0.1)

    def output(self) -> str:
        try:
            return self.log_path.read_text(errors="replace")
        except OSError:
            return ""

    @property
    def pid(self) -> int | None:
        return None if self._process is None else self._process.pid

    @property
    def alive(self) -> bool:
        return self._process is not None and self._process.poll() is None

    def close(self, timeout_s: float = 15.0) -> None:
        """Stop the simulator and everything it started (idempotent)."""
        process, self._process = self._process, None
        if process is None:
            return
        if process.poll() is None:
            process.send_signal(signal.SIGTERM)
            try:
                process.wait(timeout_s)
            except subprocess.TimeoutExpired:
                log.warning(
                    "%s did not stop within %.0f s of SIGTERM: killing its process group",
                    self.name,
                    timeout_s,
                )
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(process.pid, signal.SIGKILL)  # whatever is left of its process group
        process.wait(5.0)

    def __enter__(self) -> SimulatorProcess:
        return self.start()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()
