"""Finding a real PX4 SITL for the tests that fly it, and checking what a run left behind.

PX4 is looked for in $PX4_SITL_DIR, then in `../shared/px4-sitl` beside the checkout;
tests that need it are skipped, with that reason, when neither holds a PX4 SITL build.
CI has one, so there they run.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest

from sim_world.px4_bridge.px4_process import PX4_DIR_ENV, Px4FolderError, check_px4_dir

SHARED_PX4 = Path(__file__).resolve().parents[2] / "shared" / "px4-sitl"


def find_test_px4() -> Path | None:
    for candidate in (os.environ.get(PX4_DIR_ENV), SHARED_PX4):
        if candidate:
            try:
                return check_px4_dir(Path(candidate))
            except Px4FolderError:
                continue
    return None


PX4_DIR = find_test_px4()
requires_px4 = pytest.mark.skipif(
    PX4_DIR is None, reason=f"no PX4 SITL build: set {PX4_DIR_ENV} or put one at {SHARED_PX4}"
)


def session_members(session_id: int) -> list[tuple[int, str]]:
    """(pid, command) of every live process in a session (the simulator leads its own)."""
    members = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            state, sid = fields[0], int(fields[3])
            command = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except (OSError, IndexError, ValueError):
            continue
        if sid == session_id and state != "Z":
            members.append((int(entry.name), command.strip()))
    return members


def wait_gone(session_id: int, within_s: float) -> list[tuple[int, str]]:
    """The session's processes still alive after `within_s` (empty when all are gone)."""
    deadline = time.monotonic() + within_s
    while (left := session_members(session_id)) and time.monotonic() < deadline:
        time.sleep(0.1)
    return left
