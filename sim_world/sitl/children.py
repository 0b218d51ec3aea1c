"""Autopilot binaries as children of a bridge: found, locked to an instance number, dying with their owner.

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
import os
import signal
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO

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
