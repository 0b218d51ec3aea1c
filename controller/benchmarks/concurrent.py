"""`dronectl bench concurrent`: several `dronectl fly` started at once with their defaults, each must fly
its own vehicle into its own folder.

`n` processes `dronectl fly --vehicle V` (sim-mavlink or px4-sitl; nothing else given: default ports,
default report folders) start within a few milliseconds of each other in one working folder. Counted:

- flew: the process passed (PASS: centred, landed, disarmed);
- own folder: every run reported into a folder of its own (no two the same), holding one report;
- own vehicle: each run's .tlog holds messages from its own vehicle's system id and its own MAVSDK
  only, and no two runs share a vehicle system id or a port.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from pymavlink import mavutil

from controller.benchmarks.fuzz import CONTROLLER_IDENTITY

REPO = Path(__file__).resolve().parents[2]
_REPORT = re.compile(r"report: (\S+/report\.json)")


def _senders(tlog: Path) -> set[int]:
    """The system ids of every message in a .tlog."""
    if not tlog.is_file():
        return set()
    log = mavutil.mavlink_connection(str(tlog))
    ids = set()
    while (message := log.recv_msg()) is not None:
        ids.add(message.get_srcSystem())
    return ids


def run_concurrent(
    n: int, vehicle: str, workdir: Path, px4_dir: str | None = None, timeout_s: float = 600.0
) -> dict[str, Any]:
    """`n` flights started at once in `workdir`; the counts of the module docstring."""
    command = [sys.executable, "-m", "dronectl", "fly", "--vehicle", vehicle]
    if px4_dir is not None:
        command += ["--px4", px4_dir]
    paths = [str(REPO), str(REPO / "tools"), os.environ.get("PYTHONPATH", "")]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in paths if p)}
    load_before, started = os.getloadavg()[0], time.monotonic()
    procs = [
        subprocess.Popen(
            command, cwd=workdir, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
        )
        for _ in range(n)
    ]
    outputs = [p.communicate(timeout=timeout_s)[0] for p in procs]
    wall_s = time.monotonic() - started
    runs = []
    for proc, output in zip(procs, outputs, strict=True):
        found = _REPORT.search(output)
        report_path = (workdir / found.group(1)) if found else None
        report = json.loads(report_path.read_text()) if report_path and report_path.is_file() else {}
        setup = report.get("setup", {})
        folder = report_path.parent if report_path else None
        tlog = folder / "flight.tlog" if folder else None
        runs.append(
            {
                "exit": proc.returncode,
                "passed": proc.returncode == 0 and "PASS" in output,
                "folder": str(folder) if folder else None,
                "system_id": setup.get("system_id", setup.get("px4_system_id")),
                "ports": setup.get("ports", {}),
                "tlog_senders": sorted(_senders(tlog)) if tlog else [],
                "last_line": output.strip().splitlines()[-1] if output.strip() else "",
            }
        )
    folders = [r["folder"] for r in runs if r["folder"]]
    ids = [r["system_id"] for r in runs if r["system_id"] is not None]
    ports = [str(v) for r in runs for v in r["ports"].values()]
    own_vehicle = [
        r["system_id"] is not None and set(r["tlog_senders"]) <= {r["system_id"], CONTROLLER_IDENTITY[0]}
        for r in runs
    ]
    return {
        "n": n,
        "vehicle": vehicle,
        "runs": runs,
        "flew": sum(r["passed"] for r in runs),
        "own_folder": sum(folders.count(f) == 1 for f in folders),
        "own_vehicle": sum(own_vehicle),
        "shared_system_ids": len(ids) - len(set(ids)),
        "shared_ports": len(ports) - len(set(ports)),
        "wall_s": round(wall_s, 1),
        "load_average_before": load_before,
        "cpus": os.cpu_count(),
    }
