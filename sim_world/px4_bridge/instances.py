"""Which PX4 SITL instance a run takes: one no other run holds, and (where it uses them) whose ports are free.

PX4 instance N owns a lock file (/tmp/px4_lock-N) and a command socket (/tmp/px4-sock-N), and,
started by its own scripts, ports 4560+N, 14580+N, 18570+N, 14280+N and 13030+N. A run holds its
instance with a lock file of ours for as long as it flies; `auto` takes the lowest instance no run
and no PX4 holds. A mission chooses PX4's ports itself (`px4_process.Px4Ports`), so only the
instance's files matter to it; `dronectl px4-sim` keeps PX4's own ports, which are checked here,
before anything starts, with the port that is taken named.
"""

from __future__ import annotations

import fcntl
from collections.abc import Callable
from contextlib import AbstractContextManager
from pathlib import Path

from drone_inspect_core.ports import (
    PX4_GCS_LOCAL_UDP,
    PX4_OFFBOARD_LOCAL_UDP,
    PX4_SIMULATOR_TCP,
    Protocol,
    check_free,
    is_free,
)
from sim_world.px4_bridge.px4_process import MAX_INSTANCE
from sim_world.sitl.children import InstanceBusyError, instance_lock


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


class Px4InstanceBusyError(InstanceBusyError):
    """The PX4 instance asked for (or every instance, for `auto`) is held by another run."""


def px4_instance(
    wanted: int | str, ports: Callable[[int], list[tuple[Protocol, int, str]]] | None = None
) -> AbstractContextManager[int]:
    """Hold a PX4 instance number for the block (`sim_world.sitl.children.instance_lock`).

    `auto` skips instances another run or another PX4 holds and, with `ports` (the ports instance N
    needs, e.g. `conventional_ports`), those whose ports another program holds; a fixed instance
    whose port is taken fails here, before anything starts, with `PortInUseError` naming it.
    PX4 binds every interface, so ports are checked there (0.0.0.0)."""
    if ports is not None and wanted != "auto":
        check_free(ports(int(wanted)), host="0.0.0.0")

    def taken(n: int) -> bool:
        if _px4_running(n):
            return True
        return ports is not None and not all(is_free(port, kind, "0.0.0.0") for kind, port, _ in ports(n))

    return instance_lock("px4", wanted, MAX_INSTANCE, taken, Px4InstanceBusyError)


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
