"""`SimulatorProcess`: a simulator's own entry point (`python -m <package> --config FILE`) as a child.

The child runs in its own session, so a Ctrl-C in the terminal reaches only the
controller (which lands first and then stops the child); it watches its parent and
stops by itself within a second when the parent dies, however the parent dies. It
reads its config from a pipe (`--config -`, the first line; `secrets`, such as a run's signing key,
are added there and nowhere else: the copy of the config kept beside the log leaves them out) and
prints one line `<prefix>{json}` when it is ready; `start()` waits for that line (or for the child's
exit, reported with the end of its output) and `ready` holds the JSON.

A lockstepped simulator paced by its client (`paced=True`) keeps that pipe open for `pace()`, and one
kept warm between missions (given a `reset_prefix`) for resets: `reset(config,
log_path)` sends it a new world on one line (`drone_inspect_core.launcher_requests`), waits for its answer
line (`<reset_prefix>{json}`: the new world is built, or why not) and copies its output to the new
log from then on; the process, its ports and its autopilot stay.

The child's output comes through a pipe that a reader thread drains all the time and
copies into `log_path` as a record: a log that cannot be written (a full disk, a removed
folder) is said once and no longer copied, and never stalls the child or its start.
`close()` sends SIGTERM (the child stops its own children and writes its logs), then
SIGKILL to the whole process group if it hangs.

This module imports nothing of the simulator: a real-vehicle run never loads it.
"""

from __future__ import annotations

import contextlib
import errno
import json
import logging
import os
import signal
import subprocess
import sys
import threading
import time
from collections import deque
from pathlib import Path
from types import TracebackType
from typing import Any

from drone_inspect_core.config_files import to_json
from drone_inspect_core.files import still_there, write_json_atomic
from drone_inspect_core.launcher_requests import PACE_LINE, reset_line

log = logging.getLogger(__name__)

_TAIL_LINES = 200


class SimulatorStartError(RuntimeError):
    """The simulator exited or did not become ready; the message carries the end of its log."""


class SimulatorResetError(SimulatorStartError):
    """A warm simulator could not be reset to a new world (it refused, failed or did not answer)."""


class SimulatorProcess:
    """One simulator child process; `start()` then `close()`, or a context manager."""

    def __init__(
        self,
        module: str,
        config: Any,
        log_path: Path,
        ready_prefix: str,
        start_timeout_s: float = 90.0,
        name: str = "simulator",
        secrets: dict[str, Any] | None = None,
        reset_prefix: str | None = None,
        paced: bool = False,
    ) -> None:
        """`reset_prefix`: the child's answer to a reset request; given, the child is kept resettable
        (its stdin stays open for `reset()`). `paced`: its stdin stays open for `pace()` too."""
        self.module, self.log_path = module, Path(log_path)
        self.config: dict[str, Any] = to_json(config)
        """The child's config as JSON (`drone_inspect_core.config_files.to_json` of a config object), kept
        beside its log; `secrets` (a signing key) travel through the child's stdin only."""
        self._secrets = dict(secrets or {})
        self.ready_prefix, self.start_timeout_s, self.name = ready_prefix, start_timeout_s, name
        self.config_path = self.log_path.with_suffix(".json")
        self.ready: dict[str, Any] = {}
        self.log_error: str | None = None
        """Why the log stopped being copied to `log_path` (None while it is)."""
        self._process: subprocess.Popen[bytes] | None = None
        self._tail: deque[str] = deque(maxlen=_TAIL_LINES)
        self._ready_line = threading.Event()
        self._reader: threading.Thread | None = None
        self.reset_prefix = reset_prefix
        self._keep_stdin = reset_prefix is not None or paced
        self._stdin_lock = threading.Lock()
        self._reset_answer: dict[str, Any] | None = None
        self._reset_done = threading.Event()
        self._log_lock = threading.Lock()
        self._next_log: Path | None = None

    def start(self) -> SimulatorProcess:
        try:  # a copy for people, whole or not at all; the child reads its config from the pipe
            self.log_path.parent.mkdir(parents=True, exist_ok=True)
            write_json_atomic(self.config_path, self.config)
        except OSError as exc:
            log.warning("%s: could not keep a copy of its config in %s: %s", self.name, self.config_path, exc)
        command = [sys.executable, "-m", self.module, "--config", "-"]
        self._process = subprocess.Popen(
            command,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
        self._reader = threading.Thread(target=self._read_output, name=f"{self.name}-output", daemon=True)
        self._reader.start()
        try:
            assert self._process.stdin is not None
            self._process.stdin.write(json.dumps({**self.config, **self._secrets}).encode() + b"\n")
            self._process.stdin.flush()
            if not self._keep_stdin:
                self._process.stdin.close()
            self._wait_ready()
        except BaseException:
            self.close()
            raise
        log.info("%s ready (pid %d): %s", self.name, self._process.pid, self.ready)
        return self

    def _read_output(self) -> None:
        """Drain the child's output: keep its tail, catch the ready line, copy it to the log while it can."""
        assert self._process is not None and self._process.stdout is not None
        try:
            log_file = self.log_path.open("ab")
        except OSError as exc:
            log_file = None
            self._log_failed(exc)
        next_check_s = 0.0
        for raw in self._process.stdout:
            line = raw.decode(errors="replace").rstrip("\n")
            self._tail.append(line)
            if not self._ready_line.is_set() and line.startswith(self.ready_prefix):
                with contextlib.suppress(ValueError):
                    self.ready = json.loads(line[len(self.ready_prefix) :])
                    self._ready_line.set()
            if self.reset_prefix is not None and line.startswith(self.reset_prefix):
                try:
                    self._reset_answer = json.loads(line[len(self.reset_prefix) :])
                except ValueError:
                    self._reset_answer = {"error": f"an answer that is not JSON: {line!r}"}
                self._reset_done.set()
            with self._log_lock:
                next_log, self._next_log = self._next_log, None
            if next_log is not None:  # a reset: the new world's output goes to its own log
                if log_file is not None:
                    with contextlib.suppress(OSError):
                        log_file.close()
                self.log_path, self.log_error = next_log, None
                try:
                    log_file = next_log.open("ab")
                except OSError as exc:
                    log_file = None
                    self._log_failed(exc)
            if log_file is not None:
                try:
                    if time.monotonic() >= next_check_s:  # a removed folder gives no write error
                        next_check_s = time.monotonic() + 1.0
                        if not still_there(log_file, self.log_path):
                            raise OSError(errno.ENOENT, "the log or its folder was removed")
                    log_file.write(raw)
                    log_file.flush()
                except OSError as exc:
                    with contextlib.suppress(OSError):
                        log_file.close()
                    log_file = None
                    self._log_failed(exc)
        if log_file is not None:
            with contextlib.suppress(OSError):
                log_file.close()

    def _log_failed(self, exc: OSError) -> None:
        self.log_error = f"{self.log_path}: {exc}"
        log.error("%s: its log is no longer recorded (%s); it runs on", self.name, self.log_error)

    def _wait_ready(self) -> None:
        assert self._process is not None
        deadline = time.monotonic() + self.start_timeout_s
        while not self._ready_line.wait(0.1):
            if self._process.poll() is not None:
                if self._reader is not None:
                    self._reader.join(2.0)  # the last lines it printed
                if self._ready_line.is_set():
                    break
                raise SimulatorStartError(
                    f"{self.name} exited with {self._process.returncode} before it was ready; "
                    f"its output ends with:\n{self.output()[-2000:]}"
                )
            if time.monotonic() > deadline:
                raise SimulatorStartError(
                    f"{self.name} not ready within {self.start_timeout_s:.0f} s; "
                    f"its output ends with:\n{self.output()[-2000:]}"
                )

    def reset(self, config: Any, log_path: Path, timeout_s: float = 60.0) -> dict[str, Any]:
        """Give the warm child a new world (`config`: its whole config, of which it may change only the
        world) and copy its output to `log_path` from the answer on; the child's answer (its ready
        facts for the new world). `SimulatorResetError` when it refuses, fails, dies or is silent."""
        process = self._process
        if self.reset_prefix is None or process is None or process.stdin is None or process.stdin.closed:
            raise SimulatorResetError(f"{self.name} is not a warm simulator that can be reset")
        self.config = to_json(config)
        Path(log_path).parent.mkdir(parents=True, exist_ok=True)
        with contextlib.suppress(OSError):  # a copy for people, as at start
            write_json_atomic(Path(log_path).with_suffix(".json"), self.config)
        self._reset_done.clear()
        self._reset_answer = None
        with self._log_lock:
            self._next_log = Path(log_path)
        try:
            self._send(reset_line(self.config))
        except OSError as exc:
            raise SimulatorResetError(f"{self.name}: cannot send the reset: {exc}") from exc
        deadline = time.monotonic() + timeout_s
        while not self._reset_done.wait(0.1):
            if process.poll() is not None:
                raise SimulatorResetError(
                    f"{self.name} exited with {process.returncode} during a reset; its output ends with:\n"
                    f"{self.output()[-2000:]}"
                )
            if time.monotonic() > deadline:
                raise SimulatorResetError(f"{self.name} did not answer a reset within {timeout_s:.0f} s")
        answer = self._reset_answer or {}
        if "error" in answer:
            raise SimulatorResetError(f"{self.name} could not reset: {answer['error']}")
        self.ready = answer
        return answer

    def pace(self) -> None:
        """Tell a lockstepped child (`paced=True`) that its client waits on the vehicle's clock, so it may
        run on (`sim_world.sitl.rig.LockstepPace`); a child gone or not paced: nothing."""
        if self._keep_stdin:
            with contextlib.suppress(OSError, ValueError):
                self._send(PACE_LINE)

    def _send(self, line: bytes) -> None:
        process = self._process
        if process is None or process.stdin is None:
            raise OSError("the simulator has no open stdin")
        with self._stdin_lock:
            process.stdin.write(line)
            process.stdin.flush()

    def output(self) -> str:
        """The last lines the child printed (also in `log_path` while that can be written)."""
        return "\n".join(self._tail)

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
        if process.stdin is not None:
            with contextlib.suppress(OSError):
                process.stdin.close()
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
