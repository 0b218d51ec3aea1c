"""Autopilot binaries as children of a bridge: found, locked to an instance number, dying with their owner.

- `SitlChild`: the lifecycle both autopilots share (PX4's `Px4Process`, ArduPilot's `ArduPilotProcess`):
  a private working folder, the console in a log, SIGTERM then SIGKILL to stop it, its last words when it
  exits early, its own logs kept on request; each subclass says how to start its binary;
- `find_sitl_dir`: a SITL folder from an option, else an environment variable, else defaults; the
  error names every place looked at and why each was refused;
- `set_parent_death_signal`: for `subprocess.Popen(preexec_fn=...)`, a signal to the child when the
  process that started it dies, however it dies (SIGKILL included): no autopilot outlives its bridge;
- `instance_lock`: hold an instance number (its ports) for a block: a lock file per number, so
  parallel runs and test workers never share ports; `auto` takes the lowest free one.
"""

from __future__ import annotations

import ctypes
import errno
import fcntl
import logging
import os
import shutil
import signal
import subprocess
import tempfile
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import IO, ClassVar, TypeVar

log = logging.getLogger(__name__)

_PR_SET_PDEATHSIG = 1


def set_parent_death_signal(signum: int = signal.SIGTERM) -> None:
    """In the child before exec: `signum` when the parent dies (Linux; a no-op elsewhere)."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signum, 0, 0, 0)
    except (OSError, AttributeError):
        pass


def find_sitl_dir(
    explicit: str | Path | None,
    env_var: str,
    fallbacks: tuple[Path, ...],
    check: Callable[[Path], Path],
    option: str,
    error: type[ValueError],
    hint: str,
) -> Path:
    """`explicit` (from `option`), else $`env_var`, else the first fallback that `check` accepts.

    `check` returns the folder resolved or raises `error`; when none passes, `error` names each
    place looked at and why it was refused (or, when there was nothing to look at, says `hint`).
    """
    candidates: list[tuple[str, Path]] = []
    if explicit is not None:
        candidates.append((option, Path(explicit)))
    elif os.environ.get(env_var):
        candidates.append((f"${env_var}", Path(os.environ[env_var])))
    else:
        candidates += [("default", path) for path in fallbacks]
    if not candidates:
        raise error(f"no SITL folder given: pass {option} DIR or set {env_var} ({hint})")
    problems = []
    for source, path in candidates:
        try:
            return check(path)
        except error as exc:
            problems.append(f"{source}: {exc}")
    raise error("; ".join(problems))


class InstanceBusyError(RuntimeError):
    """The instance asked for (or every instance, for `auto`) is held by another run."""


@contextmanager
def instance_lock(
    name: str,
    wanted: int | str,
    max_instance: int,
    taken: Callable[[int], bool] = lambda n: False,
    busy_error: type[RuntimeError] = InstanceBusyError,
) -> Iterator[int]:
    """Hold instance `wanted` (or, for "auto", the lowest one `taken` does not report and no other run
    holds) for the block: a lock file `drone-inspect-<name>-N.lock` per number, released on any exit."""
    folder = Path(tempfile.gettempdir())
    candidates = range(max_instance + 1) if wanted == "auto" else [int(wanted)]
    for n in candidates:
        if wanted == "auto" and taken(n):
            continue
        handle: IO[bytes] = (folder / f"drone-inspect-{name}-{n}.lock").open("ab")
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            handle.close()
            if exc.errno in (errno.EAGAIN, errno.EACCES):
                continue
            raise
        try:
            yield n
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)
            handle.close()
        return
    which = f"every {name} instance (0..{max_instance})" if wanted == "auto" else f"{name} instance {wanted}"
    raise busy_error(f"{which} is in use by another run on this machine")


_Child = TypeVar("_Child", bound="SitlChild")


class SitlChild:
    """An autopilot binary run as a child of its bridge; `start()` (a subclass's: it builds the command
    and calls `_spawn`), then `close()` (idempotent), or a context manager.

    What differs per autopilot is said by the class attributes: its name in messages, the error for an
    early exit, the signal it gets when its parent dies, how long a SIGTERM may take, and where its own
    logs are in the working folder.
    """

    name: ClassVar[str] = "autopilot"
    start_error: ClassVar[type[Exception]] = RuntimeError
    """Raised by `check_alive` when the autopilot has exited, with the end of its console."""
    death_signal: ClassVar[int] = signal.SIGTERM
    """What the child gets when the process that started it dies, however it dies."""
    stop_timeout_s: ClassVar[float] = 5.0
    slow_stop: ClassVar[tuple[int, str]] = (logging.WARNING, "")
    """The log level and the reason said when a SIGTERM did not stop it in time (then it is killed)."""
    log_pattern: ClassVar[str] = "*.log"
    """The autopilot's own logs, a glob in the working folder, copied to `keep_logs_in` at `close()`."""

    def __init__(self, instance: int, console_log: Path | None, keep_logs_in: Path | None, console_name: str):
        self.workdir = Path(tempfile.mkdtemp(prefix=f"{self.name.lower()}-sitl-{instance}-"))
        self.console_log = console_log or self.workdir / console_name
        self._console_given = console_log is not None
        self._console_name = console_name
        self._keep_logs_in = keep_logs_in
        self._process: subprocess.Popen[bytes] | None = None
        self._log_file: IO[bytes] | None = None

    def start(self: _Child) -> _Child:
        raise NotImplementedError

    def _spawn(self, command: list[str], cwd: Path, env: Mapping[str, str] | None = None) -> None:
        """Start `command` in `cwd`, its output into the console log, dying with its parent."""
        self.console_log.parent.mkdir(parents=True, exist_ok=True)
        self._log_file = self.console_log.open("wb")
        death_signal = self.death_signal
        self._process = subprocess.Popen(
            command,
            cwd=cwd,
            env=env,
            stdin=subprocess.DEVNULL,
            stdout=self._log_file,
            stderr=subprocess.STDOUT,
            preexec_fn=lambda: set_parent_death_signal(death_signal),
        )

    @property
    def pid(self) -> int | None:
        return None if self._process is None else self._process.pid

    @property
    def alive(self) -> bool:
        return self._process is not None and self._process.poll() is None

    @property
    def returncode(self) -> int | None:
        return None if self._process is None else self._process.poll()

    def output_tail(self, chars: int = 2000) -> str:
        try:
            return self.console_log.read_text(errors="replace")[-chars:]
        except OSError:
            return ""

    def check_alive(self) -> None:
        """Raise `start_error` with the autopilot's last words if it has exited."""
        if self._process is not None and self._process.poll() is not None:
            raise self.start_error(
                f"{self.name} SITL exited with {self._process.returncode}; its console ended with:\n"
                f"{self.output_tail()}"
            )

    def terminate(self) -> None:
        """Ask the autopilot to stop (SIGTERM), without waiting."""
        if self._process is not None and self._process.poll() is None:
            self._process.send_signal(signal.SIGTERM)

    def kill(self) -> None:
        """Stop the autopilot dead (a crashed autopilot: its simulator link just goes quiet)."""
        if self._process is not None and self._process.poll() is None:
            self._process.kill()
            self._process.wait(5.0)

    def close(self, timeout_s: float | None = None) -> None:
        timeout_s = self.stop_timeout_s if timeout_s is None else timeout_s
        process, self._process = self._process, None
        if process is not None and process.poll() is None:
            process.send_signal(signal.SIGTERM)  # it shuts down its modules and closes its logs
            try:
                process.wait(timeout_s)
            except subprocess.TimeoutExpired:
                level, reason = self.slow_stop
                log.log(level, "%s did not stop within %.0f s of SIGTERM%s: killing it", self.name, timeout_s,
                        reason)  # fmt: skip
                process.kill()
                process.wait(timeout_s)
        if self._log_file is not None:
            self._log_file.close()
            self._log_file = None
        if self._keep_logs_in is not None:
            self._keep_logs(self._keep_logs_in)
        shutil.rmtree(self.workdir, ignore_errors=True)

    def _keep_logs(self, folder: Path) -> None:
        logs = sorted(self.workdir.glob(self.log_pattern))
        if not logs and self._console_given:
            return
        folder.mkdir(parents=True, exist_ok=True)
        for found in logs:
            shutil.copy2(found, folder / found.name)
        if not self._console_given and self.console_log.exists():
            shutil.copy2(self.console_log, folder / self._console_name)

    def __enter__(self: _Child) -> _Child:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()
