"""`python -m drone_inspect_core.ray_head --parent PID --port P --cpus N --temp-dir DIR`: a private Ray head for one run.

Started by `drone_inspect_core.parallel.LocalRayHead` in its own session. It runs `ray start --head --block` in a
further session of its own (so Ray's processes, the GCS, the raylet, its agents and workers, form
one process group), then watches: when the run (PID) is gone, however it went (SIGKILL included),
or on SIGTERM, it sends SIGTERM to that whole group, SIGKILL to whatever is left 3 s later, and
removes DIR. Ray started by `ray.init()` itself would leave its agents behind when the driver is
killed; this is why the head is started here.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import shutil
import signal
import subprocess
import sys
import time

POLL_S = 0.5
GRACE_S = 3.0  # a private head holds nothing worth draining for


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _stop_group(pgid: int, process: subprocess.Popen[bytes]) -> None:
    with contextlib.suppress(ProcessLookupError):
        os.killpg(pgid, signal.SIGTERM)
    deadline = time.monotonic() + GRACE_S
    while time.monotonic() < deadline:
        process.poll()
        try:
            os.killpg(pgid, 0)
        except ProcessLookupError:
            return
        time.sleep(0.2)
    with contextlib.suppress(ProcessLookupError):
        os.killpg(pgid, signal.SIGKILL)
    process.wait(timeout=5)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m drone_inspect_core.ray_head")
    parser.add_argument("--parent", type=int, required=True)
    parser.add_argument("--port", type=int, required=True)
    parser.add_argument("--cpus", type=int, required=True)
    parser.add_argument("--temp-dir", required=True)
    parser.add_argument("--object-store-mb", type=int, default=300)
    args = parser.parse_args(argv)
    stop = {"requested": False}

    def on_signal(signum: int, frame: object) -> None:
        stop["requested"] = True

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the run stops us, not the terminal
    command = [
        sys.executable, "-c", "from ray.scripts.scripts import main; main()", "start", "--head", "--block",
        f"--port={args.port}", f"--num-cpus={args.cpus}", "--node-ip-address=127.0.0.1",
        "--include-dashboard=false", "--disable-usage-stats", f"--temp-dir={args.temp_dir}",
        f"--object-store-memory={args.object_store_mb * 1024 * 1024}",
    ]  # fmt: skip
    first_parent = os.getppid()  # a change means our parent died and we were re-parented
    process = subprocess.Popen(command, stdin=subprocess.DEVNULL, start_new_session=True)
    code = 0
    try:
        while not stop["requested"] and _alive(args.parent) and os.getppid() == first_parent:
            if process.poll() is not None:
                code = process.returncode or 1
                print(f"ray_head: ray start exited with {process.returncode}", flush=True)
                break
            time.sleep(POLL_S)
    finally:
        _stop_group(process.pid, process)
        shutil.rmtree(args.temp_dir, ignore_errors=True)
    return code


if __name__ == "__main__":
    sys.exit(main())
