"""`dronectl`: the project's command line.

Each subcommand lives in its own module under `tools/` as a small `main(argv)`
that parses arguments and calls an importable function from the library. The
table below is the only registry; modules are imported lazily so that
`dronectl --help` and light commands never pay for torch or pybullet imports.
"""

from __future__ import annotations

import importlib
import logging
import sys

from flight.signals import stop_signals_as_interrupt

# name -> (module, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "demo": ("dronectl.demo_cmd", "fly a short scripted demo in the simulated world and save camera frames"),
    "collect": (
        "dronectl.collect_cmd",
        "collect a goal/sector/test image dataset: rendered in the simulated world, or flown (--vehicle)",
    ),
    "dataset": ("dronectl.dataset_cmd", "`dataset check DIR`: validate a dataset folder and count it"),
    "bench": ("dronectl.bench_cmd", "benchmarks: `bench sim|perception|flight`"),
    "sim-vehicle": (
        "dronectl.sim_vehicle_cmd",
        "serve the simulated drone as a PX4-flavoured MAVLink vehicle",
    ),
    "px4-sim": (
        "dronectl.px4_sim_cmd",
        "real PX4 SITL flying the simulated drone (lockstep), camera as MJPEG",
    ),
    "ardupilot-sim": (
        "dronectl.ardupilot_sim_cmd",
        "real ArduCopter SITL flying the simulated drone, lockstep",
    ),
    "move": ("dronectl.move_cmd", "connect to a vehicle, take off, fly one discrete move, land"),
    "train-detector": ("dronectl.train_detector_cmd", "train the image-based target detector"),
    "train": ("dronectl.train_cmd", "train the latent dynamics planner"),
    "evaluate": ("dronectl.evaluate_cmd", "evaluate a trained planner checkpoint on a dataset"),
    "reproduce": ("dronectl.reproduce_cmd", "run the paper's experiments and write a report"),
    "fly": ("dronectl.fly_cmd", "fly one centring mission and write a report"),
    "missions": ("dronectl.missions_cmd", "run a mission suite: `missions run DIR`"),
    "benchmark-missions": ("dronectl.benchmark_missions_cmd", "randomised missions, planners side by side"),
    "gym-eval": ("dronectl.gym_eval_cmd", "policies in the Gymnasium environment DroneInspect/Centring-v0"),
    "fault-matrix": ("dronectl.fault_matrix_cmd", "the same missions under each injected fault, as a table"),
}


def _usage() -> str:
    width = max(len(n) for n in COMMANDS)
    lines = ["usage: dronectl <command> [options]", "", "commands:"]
    lines += [f"  {name:<{width}}  {help_}" for name, (_, help_) in COMMANDS.items()]
    lines += ["", "`dronectl <command> --help` for a command's options."]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help", "help"):
        print(_usage())
        return 0
    name, rest = argv[0], argv[1:]
    if name not in COMMANDS:
        print(f"dronectl: unknown command {name!r}\n\n{_usage()}", file=sys.stderr)
        return 2
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    module = importlib.import_module(COMMANDS[name][0])
    try:
        with stop_signals_as_interrupt():  # SIGTERM / SIGHUP end a flight as Ctrl-C does
            return int(module.main(rest) or 0)
    except KeyboardInterrupt as exc:
        print(f"dronectl: interrupted ({exc or 'SIGINT'})", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
