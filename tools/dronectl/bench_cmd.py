"""`dronectl bench sim|perception|inference|flight|px4|ardupilot [options]`: the speed benchmarks.

Each benchmark's measuring code lives in `controller/benchmarks/` (sim, flight, px4, ardupilot,
perception, planner latency); its command line is a `tools/dronectl/bench_<name>.py` with
`main(argv) -> int`. This command only picks the module
(imported lazily, so one benchmark never pays for another's imports) and hands it the
rest of the command line. `dronectl bench <name> --help` shows a benchmark's options.
"""

from __future__ import annotations

import importlib
import sys

BENCHMARKS: dict[str, tuple[str, str]] = {
    "sim": (
        "dronectl.bench_sim",
        "physics and camera real-time factors, render times, collection throughput",
    ),
    "perception": ("dronectl.bench_perception", "detector latency, stream-camera latency, detector accuracy"),
    "inference": (
        "dronectl.bench_inference",
        "planner and detector on torch and on ONNX Runtime, side by side",
    ),
    "flight": ("dronectl.bench_flight", "vehicle command and telemetry latency"),
    "px4": ("dronectl.bench_px4", "real PX4 SITL in lockstep: readiness, hover drift, lockstep speed"),
    "ardupilot": (
        "dronectl.bench_ardupilot",
        "real ArduCopter SITL in lockstep: readiness, hover drift, speed",
    ),
    "fuzz": ("dronectl.bench_fuzz", "hostile MAVLink against flying missions: crashes, commands obeyed"),
    "disk-full": ("dronectl.bench_disk_full", "the disk fills mid-flight: landed by the controller?"),
    "console": (
        "dronectl.bench_console",
        "the console in a browser: page fps, camera-to-page latency, Hold to HOLD mode",
    ),
    "concurrent": (
        "dronectl.bench_concurrent",
        "several `fly` at once with defaults: own vehicle, own folder",
    ),
    "missions": (
        "dronectl.bench_missions",
        "the same missions each way (in-process, sim-mavlink, PX4, ArduPilot): phases and ratios",
    ),
}


def _usage() -> str:
    lines = ["usage: dronectl bench <benchmark> [options]", "", "benchmarks:"]
    lines += [f"  {name:<11} {help_}" for name, (_, help_) in BENCHMARKS.items()]
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    if not argv or argv[0] in ("-h", "--help"):
        print(_usage())
        return 0
    name, rest = argv[0], argv[1:]
    if name not in BENCHMARKS:
        print(f"dronectl bench: unknown benchmark {name!r} (one of {', '.join(BENCHMARKS)})", file=sys.stderr)
        return 2
    module = importlib.import_module(BENCHMARKS[name][0])
    return int(module.main(rest) or 0)
