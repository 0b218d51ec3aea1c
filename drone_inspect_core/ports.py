"""Ports, in one place: the conventions of the programs we talk to, and free ports chosen per run.

A run that starts its own vehicle (sim-vehicle, PX4 SITL, ArduPilot SITL) takes ports nobody holds,
checked before anything starts: where a program lets us, a socket binds port 0 and the kernel picks
(nothing to race for); where a client needs a number first (MAVSDK's `udpin://`), `free_port` draws
one below the kernel's ephemeral range, where no port-0 socket of another process can take it. A port
a user fixes is checked with `check_free`, which names the port taken.

The fixed numbers below are conventions of other programs, not choices of ours: PX4 SITL instance N
listens and sends on `base + N`, as its own start scripts say.
"""

from __future__ import annotations

import errno
import random
import socket
from collections.abc import Iterable
from pathlib import Path
from typing import Literal

Protocol = Literal["udp", "tcp"]
LOOPBACK = "127.0.0.1"

# PX4 SITL, instance N (PX4's px4-rc.mavlink and px4-rc.simulator add N to each).
PX4_SIMULATOR_TCP = 4560
"""PX4 dials its simulator here (TCP client)."""
PX4_OFFBOARD_REMOTE_UDP = 14540
"""PX4 sends its offboard/API link here (MAVSDK listens: `udpin://0.0.0.0:14540`)."""
PX4_OFFBOARD_LOCAL_UDP = 14580
"""PX4's offboard link listens here."""
PX4_GCS_LOCAL_UDP = 18570
"""PX4's ground-station link listens here (it sends to 14550)."""
GCS_UDP = 14550
"""Where ground stations (QGroundControl) listen."""

SIM_VEHICLE_VIDEO_HTTP = 8080
"""`dronectl sim-vehicle` / `px4-sim` serve MJPEG on 8080 + N when run by hand (a camera-like port)."""

# ArduPilot SITL, instance N (ArduPilot adds ARDUPILOT_PORT_STRIDE · N to each).
ARDUPILOT_PORT_STRIDE = 10
ARDUPILOT_JSON_UDP = 9002
"""ArduPilot sends its JSON physics frames here (the bridge listens)."""
ARDUPILOT_MAVLINK = 5760
"""ArduPilot's SERIAL0 port number; here the UDP port it sends its MAVLink to."""
ARDUPILOT_VIDEO_HTTP = 8090
"""`dronectl ardupilot-sim` serves MJPEG on 8090 + N when run by hand, beside px4-sim's 8080 + N."""


class PortInUseError(OSError):
    """A port a run needs is held by another program; the message names it."""


CHOSEN_PORTS = (20000, 32768)
"""Where `free_port` looks first: above every fixed port here, below Linux's ephemeral range."""
EPHEMERAL_RANGE_FILE = Path("/proc/sys/net/ipv4/ip_local_port_range")


def free_port(protocol: Protocol = "udp", host: str = LOOPBACK) -> int:
    """A port on `host` that nobody holds now, for a client that must be told a number before it binds.

    A port the kernel hands out for "port 0" could be handed to any other process's socket in the moment
    before the client binds it (MAVSDK once failed with BIND_ERROR that way, under a parallel test run).
    So the port is drawn at random below the kernel's ephemeral range (`CHOSEN_PORTS`, where the kernel
    never picks) and checked free; only where that range cannot be read or holds nothing free is it the
    kernel's pick."""
    low, high = CHOSEN_PORTS
    high = min(high, _ephemeral_low())
    if high - low > 1000:
        draw = random.SystemRandom()
        for _ in range(64):
            port = draw.randrange(low, high)
            if is_free(port, protocol, host):
                return port
    kind = socket.SOCK_DGRAM if protocol == "udp" else socket.SOCK_STREAM
    with socket.socket(socket.AF_INET, kind) as sock:
        sock.bind((host, 0))
        return int(sock.getsockname()[1])


def _ephemeral_low() -> int:
    """The lowest port of the kernel's ephemeral range (0: unknown, so `free_port` asks the kernel)."""
    try:
        return int(EPHEMERAL_RANGE_FILE.read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return 0


def is_free(port: int, protocol: Protocol = "udp", host: str = LOOPBACK) -> bool:
    """Whether `port` can be bound on `host` now."""
    kind = socket.SOCK_DGRAM if protocol == "udp" else socket.SOCK_STREAM
    with socket.socket(socket.AF_INET, kind) as sock:
        if protocol == "tcp":
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as servers bind: TIME_WAIT is free
        try:
            sock.bind((host, port))
        except OSError as exc:
            if exc.errno in (errno.EADDRINUSE, errno.EACCES):
                return False
            raise
        return True


def check_free(ports: Iterable[tuple[Protocol, int, str]], host: str = LOOPBACK) -> None:
    """Raise `PortInUseError` naming the first of `ports` ((protocol, port, what it is for)) that is taken."""
    for protocol, port, what in ports:
        if not is_free(port, protocol, host):
            raise PortInUseError(
                errno.EADDRINUSE,
                f"{protocol.upper()} port {port} ({what}) is in use by another program; "
                "free it, or leave the ports to the run (auto)",
            )
