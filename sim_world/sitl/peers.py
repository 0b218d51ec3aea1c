"""Which local process owns the other end of a loopback socket (Linux /proc), so a bridge takes its
autopilot and no other local program: PX4's simulator connection (TCP) and ArduPilot's physics frames
(UDP). A socket is found by its addresses in /proc/net/tcp or /proc/net/udp, then among the process's
open files (/proc/PID/fd). Whatever cannot be told is no: an end we cannot vouch for is not the
autopilot's."""

from __future__ import annotations

import contextlib
import os
import socket
from collections.abc import Callable


def tcp_connection_owned_by(conn: socket.socket, pid: int) -> bool:
    """Whether process `pid` owns the other end of the loopback TCP connection `conn`."""
    try:
        peer, local = conn.getpeername(), conn.getsockname()
    except OSError:
        return False
    want_local, want_remote = _hexed(peer), _hexed(local)  # the other end's row: bound there, connected here
    inodes = _inodes("/proc/net/tcp", lambda fields: fields[1] == want_local and fields[2] == want_remote)
    return _owns_one_of(pid, inodes)


def udp_sender_owned_by(sender: tuple[str, int], pid: int) -> bool:
    """Whether process `pid` owns the UDP socket that datagrams from `sender` (IPv4) come from: the
    socket bound to that address, or to that port on every interface."""
    try:
        wanted = {_hexed(sender), _hexed(("0.0.0.0", sender[1]))}
    except (OSError, ValueError, OverflowError):
        return False
    return _owns_one_of(pid, _inodes("/proc/net/udp", lambda fields: fields[1] in wanted))


def _hexed(address: tuple[str, int]) -> str:
    """An IPv4 address as /proc/net's tables write it (the address in host order, then the port)."""
    packed = socket.inet_aton(address[0])
    return f"{int.from_bytes(packed, 'little'):08X}:{address[1]:04X}"


def _inodes(table: str, wanted: Callable[[list[str]], bool]) -> set[int]:
    """The inodes of the sockets in the /proc/net `table` whose row `wanted(fields)` picks."""
    found = set()
    try:
        with open(table) as rows:
            for line in rows.readlines()[1:]:
                fields = line.split()
                if len(fields) > 9 and wanted(fields):
                    found.add(int(fields[9]))
    except (OSError, ValueError):
        return set()
    found.discard(0)
    return found


def _owns_one_of(pid: int, inodes: set[int]) -> bool:
    """Whether process `pid` has one of the sockets `inodes` open."""
    if not inodes:
        return False
    wanted = {f"socket:[{inode}]" for inode in inodes}
    try:
        fds = os.listdir(f"/proc/{pid}/fd")
    except OSError:
        return False
    for fd in fds:
        with contextlib.suppress(OSError):
            if os.readlink(f"/proc/{pid}/fd/{fd}") in wanted:
                return True
    return False
