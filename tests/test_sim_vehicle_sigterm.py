"""`dronectl sim-vehicle` stops on a SIGTERM sent to its whole process group, video render process included.

This is what `timeout 20 dronectl sim-vehicle` does (and a supervisor, or a terminal
closing): the render process is killed at once, and the vehicle must not hang while
stopping it. Ports 14890-14891 and 18890 (this file's share of the missions range).
"""

from __future__ import annotations

import os
import select
import signal
import subprocess
import sys
import time

LOCAL_PORT, REMOTE_PORT, VIDEO_PORT = 14890, 14891, 18890


def test_sigterm_to_the_process_group_stops_sim_vehicle_with_video() -> None:
    command = [
        sys.executable, "-m", "dronectl", "sim-vehicle", "--local-port", str(LOCAL_PORT),
        "--remote-port", str(REMOTE_PORT), "--video-port", str(VIDEO_PORT), "--status-every", "0",
        "--size", "64", "--video-fps", "5",
    ]  # fmt: skip
    proc = subprocess.Popen(
        command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True
    )
    try:
        assert proc.stdout is not None
        assert select.select([proc.stdout], [], [], 60.0)[0], "no ready line within 60 s"
        assert "sim-vehicle ready" in proc.stdout.readline()
        time.sleep(0.5)  # the render process is serving frames
        t0 = time.monotonic()
        os.killpg(proc.pid, signal.SIGTERM)  # as `timeout` does: the whole group
        out, err = proc.communicate(timeout=20)
        assert time.monotonic() - t0 < 10.0
        assert proc.returncode == 0, err
        assert "simulated in" in out
        # The render process and multiprocessing's resource tracker go too (the tracker once its pipe closes).
        assert _group_gone(proc.pid, within_s=10.0), "a process of sim-vehicle's group outlived it"
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(5)


def _group_gone(pgid: int, within_s: float) -> bool:
    deadline = time.monotonic() + within_s
    while time.monotonic() < deadline:
        try:
            os.killpg(pgid, 0)
        except ProcessLookupError:
            return True
        time.sleep(0.1)
    return False
