"""`dronectl`: the project's command line.

Each subcommand lives in its own module under `tools/` as a small `main(argv)`
that parses arguments and calls an importable function from the library. The
table below is the only registry; modules are imported lazily so that
`dronectl --help` and light commands never pay for torch or pybullet imports.

Whatever a command meets, the user gets one line on stderr and a non-zero exit, never a traceback:
an error no command caught is said here as `dronectl <command>: <what>` (exit 1); `dronectl --debug
<command> ...` shows the traceback (and third-party logs) instead. SIGINT exits 130, SIGTERM 143,
SIGHUP 129, as the shell expects of a process a signal ended, after the flight has landed. Libraries
that print on their own (OpenCV and FFmpeg on a bad stream URL, PyBullet when it loads, Python
warnings) are kept quiet unless --debug.
"""

from __future__ import annotations

import importlib
import logging
import os
import sys
import traceback
import warnings

from dronectl import options
from flight.signals import StopRequested, stop_signals_as_interrupt

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
    "train-colour": ("dronectl.train_colour_cmd", "train the learned trim-colour reader"),
    "train": ("dronectl.train_cmd", "train the latent dynamics planner"),
    "evaluate": ("dronectl.evaluate_cmd", "evaluate a trained planner checkpoint on a dataset"),
    "calibrate-presence": (
        "dronectl.calibrate_presence_cmd",
        "choose the planner's 'not in view' threshold on validation scenes, into its checkpoint",
    ),
    "reproduce": ("dronectl.reproduce_cmd", "run the paper's experiments and write a report"),
    "fly": ("dronectl.fly_cmd", "fly one centring mission and write a report"),
    "console": ("dronectl.console_cmd", "the operator's live console in the browser"),
    "missions": ("dronectl.missions_cmd", "run a mission suite: `missions run DIR`"),
    "benchmark-missions": ("dronectl.benchmark_missions_cmd", "randomised missions, planners side by side"),
    "gym-eval": ("dronectl.gym_eval_cmd", "policies in the Gymnasium environment DroneInspect/Centring-v0"),
    "fault-matrix": ("dronectl.fault_matrix_cmd", "the same missions under each injected fault, as a table"),
}


def _usage() -> str:
    width = max(len(n) for n in COMMANDS)
    lines = ["usage: dronectl <command> [options]", "", "commands:"]
    lines += [f"  {name:<{width}}  {help_}" for name, (_, help_) in COMMANDS.items()]
    lines += [
        "",
        "`dronectl <command> --help` for a command's options; `dronectl --debug <command> ...` shows the",
        "traceback of an error (and third-party logs) instead of one line.",
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    debug = False
    while argv and argv[0] == "--debug":
        debug, argv = True, argv[1:]
    if not argv or argv[0] in ("-h", "--help", "help"):
        print(_usage())
        return 0
    name, rest = argv[0], argv[1:]
    if name not in COMMANDS:
        print(f"dronectl: unknown command {name!r} (`dronectl --help` lists them)", file=sys.stderr)
        return 2
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    quiet_third_party(debug)
    options.DEBUG = debug
    try:
        module = importlib.import_module(COMMANDS[name][0])
        with stop_signals_as_interrupt():  # SIGTERM / SIGHUP end a flight as Ctrl-C does
            return int(module.main(rest) or 0)
    except StopRequested as exc:
        print(f"dronectl: interrupted ({exc})", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print("dronectl: interrupted (SIGINT)", file=sys.stderr)
        return 130
    except Exception as exc:  # the last line of defence: one line, no traceback
        if debug:
            traceback.print_exc()
        print(f"dronectl {name}: {describe_error(exc)}", file=sys.stderr)
        return 1


def describe_error(exc: BaseException) -> str:
    """One line for an error: its message, with its type where the message alone would not say what it is
    (a KeyError's message is only the key)."""
    text = " ".join(str(exc).split())
    if not text:
        return type(exc).__name__
    if type(exc).__module__ != "builtins" or isinstance(exc, ValueError | OSError):
        return text
    return f"{type(exc).__name__}: {text}"


def quiet_third_party(debug: bool) -> None:
    """OpenCV's and FFmpeg's own logs (a stream URL that does not open prints a dozen lines before our
    one) and Python warnings go quiet, unless `debug`. Set before OpenCV loads: it reads them then."""
    if debug:
        logging.captureWarnings(True)
        return
    os.environ.setdefault("OPENCV_LOG_LEVEL", "OFF")
    os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")  # AV_LOG_QUIET
    warnings.simplefilter("ignore")


if __name__ == "__main__":
    sys.exit(main())
