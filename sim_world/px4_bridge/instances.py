"""Which PX4 SITL instance a run takes: one no other run holds, and (where it uses them) whose ports are free.

PX4 instance N owns a lock file (/tmp/px4_lock-N) and a command socket (/tmp/px4-sock-N), and,
started by its own scripts, ports 4560+N, 14580+N, 18570+N, 14280+N and 13030+N. A run holds its
instance with a lock file of ours for as long as it flies; `auto` takes the lowest instance no run
and no PX4 holds. A mission chooses PX4's ports itself (`px4_process.Px4Ports`), so only the
instance's files matter to it; `dronectl px4-sim` keeps PX4's own ports, which are checked here,
before anything starts, with the port that is taken named.
"""

from __future__ import annotations

import errno
import fcntl
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO

from drone_inspect_core.ports import (
    PX4_GCS_LOCAL_UDP,
    PX4_OFFBOARD_LOCAL_UDP,
    PX4_SIMULATOR_TCP,
    Protocol,
    check_free,
    is_free,
)
from sim_world.px4_bridge.px4_process import MAX_INSTANCE


def conventional_ports(instance: int) -> list[tuple[Protocol, int, str]]:
    """The ports PX4's own start scripts give instance N and that must be free for it (where PX4 sends,
    14540+N, is a client's to hold)."""
    return [
        ("tcp", PX4_SIMULATOR_TCP + instance, f"PX4 instance {instance}'s simulator port"),
        ("udp", PX4_OFFBOARD_LOCAL_UDP + instance, f"PX4 instance {instance}'s offboard link"),
        ("udp", PX4_GCS_LOCAL_UDP + instance, f"PX4 instance {instance}'s ground-station link"),
        ("udp", 14280 + instance, f"PX4 instance {instance}'s payload link"),
        ("udp", 13030 + instance, f"PX4 instance {instance}'s gimbal link"),
    ]


class Px4InstanceBusyError(RuntimeError):
    """The PX4 instance asked for (or every instance, for `auto`) is held by another run."""


@contextmanager
def px4_instance(
    wanted: int | str, ports: Callable[[int], list[tuple[Protocol, int, str]]] | None = None
) -> Iterator[int]:
    """Hold a PX4 instance number for the block: a lock file per instance, released on any exit.

    `auto` skips instances another run or another PX4 holds and, with `ports` (the ports instance N
    needs, e.g. `conventional_ports`), those whose ports another program holds; a fixed instance
    whose port is taken fails here, before anything starts, with `PortInUseError` naming it.
    PX4 binds every interface, so ports are checked there (0.0.0.0)."""
    folder = Path(tempfile.gettempdir())
    candidates = range(MAX_INSTANCE + 1) if wanted == "auto" else [int(wanted)]
    for n in candidates:
        if wanted == "auto" and _px4_running(n):
            continue
        if ports is not None:
            if wanted == "auto" and not all(is_free(port, kind, "0.0.0.0") for kind, port, _ in ports(n)):
                continue
            check_free(ports(n), host="0.0.0.0")
        handle: IO[bytes] = (folder / f"drone-inspect-px4-{n}.lock").open("ab")
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
    which = "every PX4 instance (0..9)" if wanted == "auto" else f"PX4 instance {wanted}"
    held = " or its ports are held by other programs" if ports is not None and wanted == "auto" else ""
    raise Px4InstanceBusyError(f"{which} is in use by another run on this machine{held}")


def _px4_running(instance: int) -> bool:
    """Whether some PX4 (ours or not) holds PX4's own lock for this instance (/tmp/px4_lock-N)."""
    path = Path(f"/tmp/px4_lock-{instance}")
    if not path.exists():
        return False
    try:
        with path.open("rb") as handle:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            fcntl.flock(handle, fcntl.LOCK_UN)
    except OSError:
        return True
    return False
