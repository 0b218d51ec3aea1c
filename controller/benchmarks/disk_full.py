"""`dronectl bench disk-full`: the disk fills at a random moment of a flight; every flight must still end
landed by the controller, with its outcome reported.

Each mission (sim-mavlink, the shipped planner, scenes drawn from the seed) writes its report folder
on a tmpfs of its own (`size_kb`, mounted for it: needs root), and a filler writes into that disk until
it is full once the flight's .tlog has reached a random size (so at a random moment between the link
coming up and the end of the flight). Counted:

- landed by the controller: the flight ended with the controller's own land and disarm, confirmed
  from telemetry (no flight error), not by the vehicle's failsafe;
- outcome reported: on the console (the result), and in a complete report.json (status finished),
  whatever else could not be written (said in `recording_errors`);
- left as if whole: any `.tmp` file, the report's ballast or claim, a .tlog not renamed incomplete
  after its recording stopped early, an image that does not decode (none expected).
"""

from __future__ import annotations

import contextlib
import errno
import json
import logging
import os
import random
import subprocess
import threading
import time
from collections.abc import Iterator, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from controller.missions.kits.base import TLOG_NAME
from controller.missions.runner import run_mission
from controller.missions.schema import Mission

log = logging.getLogger(__name__)


class MountError(OSError):
    """A tmpfs could not be mounted (mounting needs root)."""


@contextlib.contextmanager
def mounted_tmpfs(where: Path, size_kb: int, read_only: bool = False) -> Iterator[Path]:
    """A tmpfs of `size_kb` kB mounted at `where` (created), unmounted afterwards; `MountError` if it
    cannot be (mounting needs root)."""
    where.mkdir(parents=True, exist_ok=True)
    options = f"size={size_kb}k" + (",ro" if read_only else "")
    done = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(where)], capture_output=True, text=True
    )
    if done.returncode != 0:
        raise MountError(errno.EPERM, f"cannot mount a {size_kb} kB tmpfs at {where}: {done.stderr.strip()}")
    try:
        yield where
    finally:
        subprocess.run(["umount", "-l", str(where)], capture_output=True)


def fill(folder: Path) -> int:
    """Write into `folder` until its filesystem is full; the bytes written."""
    written = 0
    with contextlib.suppress(OSError), (folder / "filler").open("wb") as file:
        while True:
            file.write(b"\0" * 4096)
            file.flush()
            written += 4096
    return written


@dataclass
class DiskFullRun:
    name: str
    outcome: str
    fill_at_tlog_bytes: int
    filled_during_flight: bool
    landed_by_controller: bool
    reported_on_console: bool
    report_complete: bool
    recording_errors: list[str]
    left_as_if_whole: list[str]
    error: str | None


def _leftovers(folder: Path, recording_errors: Sequence[str]) -> list[str]:
    """Files that look whole but are not, or should not be there after a flight."""
    import cv2

    bad = []
    if any(TLOG_NAME in e for e in recording_errors) and (folder / TLOG_NAME).exists():
        bad.append(f"{TLOG_NAME} (its recording stopped early, yet it keeps the name of a whole one)")
    for path in sorted(folder.rglob("*")):
        name = path.name
        if name.endswith(".tmp") or name in (".reserve", ".claim"):
            bad.append(name)
        elif (name.endswith(".png") and cv2.imread(str(path)) is None) or (
            name.endswith(".gif") and not cv2.VideoCapture(str(path)).read()[0]
        ):
            bad.append(f"{name} (does not decode)")
    return bad


def fly_on_a_filling_disk(mission: Mission, disk: Path, fill_at_tlog_bytes: int) -> DiskFullRun:
    """One mission whose disk is filled once its .tlog reaches `fill_at_tlog_bytes`."""
    out = disk / "report"
    filled = threading.Event()
    done = threading.Event()

    def filler() -> None:
        while not done.is_set():
            try:
                if (out / TLOG_NAME).stat().st_size >= fill_at_tlog_bytes:
                    break
            except OSError:
                pass
            time.sleep(0.01)
        if not done.is_set():
            fill(disk)
            filled.set()

    thread = threading.Thread(target=filler, name="disk-filler", daemon=True)
    thread.start()
    result, error = None, None
    try:
        result = run_mission(mission, out, media=True)
    except Exception as exc:
        error = f"{type(exc).__name__}: {exc}"
    during = filled.is_set()
    done.set()
    thread.join(10.0)
    report_complete = False
    with contextlib.suppress(OSError, ValueError):
        report_complete = json.loads((out / "report.json").read_text())["status"] == "finished"
    return DiskFullRun(
        name=mission.name,
        outcome="error" if result is None else result.outcome,
        fill_at_tlog_bytes=fill_at_tlog_bytes,
        filled_during_flight=during,
        landed_by_controller=result is not None and result.error is None,
        reported_on_console=result is not None,
        report_complete=report_complete,
        recording_errors=[] if result is None else list(result.recording_errors),
        left_as_if_whole=_leftovers(out, result.recording_errors if result else ()) if out.exists() else [],
        error=error if result is None else result.error,
    )


def run_disk_full(
    base: Mission, root: Path, n: int = 20, seed: int = 0, size_kb: int = 2048, max_tlog_kb: int = 90
) -> dict[str, Any]:
    """`n` missions, each on its own `size_kb` tmpfs under `root`, filled at a random .tlog size up to
    `max_tlog_kb`; the counts of the module docstring."""
    rng = random.Random(seed)
    runs: list[DiskFullRun] = []
    started, load_before = time.monotonic(), os.getloadavg()[0]
    for i in range(n):
        mission = base.with_seed(seed * 1000 + i).model_copy(update={"name": f"disk-full-{i:02d}"})
        at_bytes = rng.randint(4 * 1024, max_tlog_kb * 1024)
        with mounted_tmpfs(root / f"disk-{i:02d}", size_kb) as disk:
            run = fly_on_a_filling_disk(mission, disk, at_bytes)
        log.info("%s: %s, landed by the controller %s", run.name, run.outcome, run.landed_by_controller)
        runs.append(run)
    return {
        "n": n,
        "seed": seed,
        "size_kb": size_kb,
        "runs": [asdict(r) for r in runs],
        "filled_during_flight": sum(r.filled_during_flight for r in runs),
        "landed_by_controller": sum(r.landed_by_controller for r in runs),
        "reported_on_console": sum(r.reported_on_console for r in runs),
        "report_complete": sum(r.report_complete for r in runs),
        "left_as_if_whole": sum(len(r.left_as_if_whole) for r in runs),
        "centred": sum(r.outcome == "centred" for r in runs),
        "wall_s": round(time.monotonic() - started, 1),
        "load_average_before": load_before,
        "cpus": os.cpu_count(),
    }
