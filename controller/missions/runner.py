"""Fly one mission: build its vehicle, camera, detector and planner, run the centring loop, write the report.

`run_mission(mission, out_dir)` builds a `FlightKit` for the mission's vehicle:

- `vehicle: sim`: the in-process PyBullet world (`flight.pybullet_backend`) and
  its rendered camera; truth from the world. Faster than real time.
- `vehicle: sim-mavlink`: `dronectl sim-vehicle` as a subprocess (the same world
  served as a PX4-flavoured MAVLink vehicle and an MJPEG stream), flown with the
  MAVSDK backend and the stream camera exactly as a real drone; truth from the
  sim's `/truth.json` endpoint, for judging only (`controller.missions.kits.sim_mavlink`).
- `vehicle: px4-sitl` / `ardupilot-sitl`: real autopilot firmware (SITL) flying that world in
  lockstep through a bridge (`kits.px4_sitl`, `kits.ardupilot_sitl`), flown as a real vehicle.
- a MAVLink URL: a real vehicle (PX4 or ArduPilot) and the `camera` stream URL; no truth.

`fly_kit(kit, mission, out_dir)` then flies: connect → ready → arm → take off →
(sim: place the drone at the mission's start pose) → zero setpoint → offboard →
the centring loop → hold → leave offboard → land → disarm. Everything runs
inside `flight_guard`, so Ctrl-C or any error ends with hold + land, and the
report (written after every step) keeps every step recorded before it.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import replace
from pathlib import Path

from controller.missions.kits.base import FlightKit, LoadedModels
from controller.missions.phases import flight_phases
from controller.missions.report import (
    REPORT_JSON,
    ReportWriter,
    claim_report_dir,
    hold_reserve,
    write_setup_failure,
)
from controller.missions.results import MissionResult, count_steps, judge, wrong_target
from controller.missions.schema import ARDUPILOT_SITL, PX4_SITL, SIM, SIM_MAVLINK, Mission
from controller.planning.grounding import TargetQuery, understand
from controller.planning.loop import CentringLoop
from controller.planning.loop_records import (
    CentringConfig,
    Outcome,
    StepRecord,
    count_refinements,
    count_second_choices,
)
from drone_inspect_core.centring import default_epsilon_px
from drone_inspect_core.signing import SigningKey
from drone_inspect_core.vocabulary import Vocabulary
from flight.moves import Milestones, take_off_to_start
from flight.safe_vehicle import SafeVehicle
from flight.safety import SafetyLimits, flight_guard
from flight.signals import StopRequested

log = logging.getLogger(__name__)

FAST_SIM_FRESH_FRAME_S = 0.1
"""A sim-vehicle off real time: a frame must arrive this long after an observation begins (render,
JPEG and HTTP take a few tens of ms of wall time, which at ×8 are a few tenths of a simulated second)."""


def epsilon_for(mission: Mission, kit: FlightKit) -> float:
    """ε for this flight: the kit's (tests fix it), else the mission's, else the default for the width."""
    return kit.epsilon_px or mission.epsilon_px or default_epsilon_px(kit.image_width_px)


def mission_vocabulary(mission: Mission) -> Vocabulary:
    """The words of a mission: the shipped ones, the kinds of its scene (a file's too, for a simulated
    vehicle) and of the mission itself, and its glossary."""
    if mission.is_real:
        return mission.vocabulary
    from controller.missions.setup import scene_config_for  # the simulator's scene code: simulated only

    return scene_config_for(mission).vocabulary.with_glossary(mission.glossary_words())


def loop_config(
    mission: Mission,
    epsilon_px: float,
    instruction: str,
    target: TargetQuery | None = None,
    vocabulary: Vocabulary | None = None,
) -> CentringConfig:
    """The loop's configuration for a flight of `mission`. The instruction is understood here, before
    anything flies: one the vocabulary cannot act on raises `InstructionRefused` naming its word."""
    vocabulary = vocabulary or mission_vocabulary(mission)
    return CentringConfig(
        **mission.loop.model_dump(),
        epsilon_px=epsilon_px,
        instruction=instruction,
        target=target or understand(instruction, vocabulary),
        vocabulary=vocabulary,
        max_steps=mission.max_steps,
        timeout_s=mission.timeout_s,
        stop_margin_px=mission.stop_margin_px,
        **({"fresh_frame_s": FAST_SIM_FRESH_FRAME_S} if off_real_time(mission) else {}),
    )


def off_real_time(mission: Mission) -> bool:
    """Whether the mission's simulator runs off real time (sim-mavlink's `sim_speed`, a SITL's `speed`):
    its camera's frames then lag the vehicle by more than at ×1, on the vehicle's clock."""
    speeds = {
        SIM_MAVLINK: mission.sim_speed,
        PX4_SITL: mission.px4.speed,
        ARDUPILOT_SITL: mission.ardupilot.speed,
    }
    return speeds.get(mission.vehicle, 1.0) != 1.0


def fly_kit(
    kit: FlightKit,
    mission: Mission,
    out_dir: str | Path,
    limits: SafetyLimits | None = None,
    media: bool = True,
    rerun_path: Path | None = None,
) -> MissionResult:
    """Fly the centring loop with `kit` and write the report folder; never loses a recorded step.
    `rerun_path`: also record the flight to this new .rrd file (`controller.missions.rerun_log`)."""
    out_dir = Path(out_dir)
    clock = Milestones()  # on the vehicle's clock (PX4 SITL's: simulated time), and each on the wall clock
    kit = replace(kit, epsilon_px=epsilon_for(mission, kit))  # ε resolved here, once, for every kit
    # A kit may bring its vehicle already behind the safety limits (the in-process sim does).
    vehicle = kit.vehicle if isinstance(kit.vehicle, SafeVehicle) else SafeVehicle(kit.vehicle, limits)
    header = {
        "mission": mission.name,
        "tags": list(mission.tags),
        "planner": kit.planner.name,
        "epsilon_px": kit.epsilon_px,
        "instruction": kit.instruction,
        "vehicle": mission.vehicle,
        "camera": mission.camera,
        "setup": kit.info,
        "mission_file": mission.model_dump(mode="json"),
    }
    loop = CentringLoop(
        vehicle,
        kit.camera,
        kit.detector,
        kit.planner,
        loop_config(mission, kit.epsilon_px, kit.instruction, kit.target),
        truth_probe=kit.truth_probe,
    )
    loop.stop_threshold_px(kit.image_width_px)  # ε against the stopping margin: checked before takeoff
    writer = ReportWriter(out_dir, header, kit.epsilon_px, media=media)
    recorder = None
    if rerun_path is not None:
        from controller.missions.rerun_log import RerunRecorder

        recorder = RerunRecorder(rerun_path, kit.epsilon_px, header)
    loop.on_step = (
        writer.add_step
        if recorder is None
        else _both(writer.add_step, _guarded(recorder.add_step, "the Rerun recording", writer))
    )
    outcome, message, error = Outcome.ABORTED, "", None
    vehicle_start_s = vehicle_end_s = 0.0
    targets_truth: list[tuple[float, float] | None] | None = None  # every target, when the loop ended
    try:
        vehicle.connect()
        clock["connected_s"] = vehicle.time_s()
        with flight_guard(vehicle):
            altitude_m = kit.takeoff_altitude_m or mission.takeoff_altitude_m
            take_off_to_start(vehicle, altitude_m, kit.place_at_start, clock)
            vehicle_start_s = vehicle.time_s()
            result = loop.run()
            outcome, message = result.outcome, result.message
            targets_truth = kit.targets_truth() if kit.targets_truth is not None else None
            vehicle_end_s = clock["loop_end_s"] = vehicle.time_s()
            vehicle.stop_offboard()
            vehicle.land()
            vehicle.disarm()
            clock["landed_s"] = vehicle.time_s()
    except KeyboardInterrupt as exc:
        how = str(exc) if isinstance(exc, StopRequested) else "stopped by Ctrl-C"
        error = message = f"interrupted ({how}); a vehicle in the air was held, then landed"
        raise
    except Exception as exc:
        error = message = f"{type(exc).__name__}: {exc}"
        log.error("mission %s aborted: %s", mission.name, error)
    finally:
        if recorder is not None:
            try:
                recorder.finish(outcome.value, message)
            except Exception as exc:
                writer.recording_errors.append(f"the Rerun recording: {exc}")
                log.error("the Rerun recording could not be finished: %s", exc)
        mission_result = _finish(
            kit, mission, writer, loop, outcome, message, error, time.perf_counter() - clock.started,
            max(0.0, vehicle_end_s - vehicle_start_s), clock, targets_truth,
        )  # fmt: skip
    return mission_result


def _guarded(
    record: Callable[[StepRecord], None], what: str, writer: ReportWriter
) -> Callable[[StepRecord], None]:
    """`record`, stopped (and said once, in the report too) at its first failure: a recording that
    fails never ends a flight."""
    failed = False

    def on_step(step: StepRecord) -> None:
        nonlocal failed
        if failed:
            return
        try:
            record(step)
        except Exception as exc:
            failed = True
            writer.recording_errors.append(f"{what}: {exc}")
            log.error("%s stopped: %s; the flight goes on", what, exc)

    return on_step


def _both(
    first: Callable[[StepRecord], None], second: Callable[[StepRecord], None]
) -> Callable[[StepRecord], None]:
    def on_step(step: StepRecord) -> None:
        first(step)
        second(step)

    return on_step


def _finish(
    kit: FlightKit,
    mission: Mission,
    writer: ReportWriter,
    loop: CentringLoop,
    outcome: Outcome,
    message: str,
    error: str | None,
    wall_s: float,
    vehicle_s: float,
    clock: Milestones,
    targets_truth: list[tuple[float, float] | None] | None,
) -> MissionResult:
    steps = loop.steps
    phases = flight_phases(clock.wall_s, [s.timing for s in steps])
    final_truth = steps[-1].truth_offset_px if steps else None
    final_detector = steps[-1].offset_px if steps else None
    n_steps = count_steps(steps)
    wrong = wrong_target(outcome, kit.epsilon_px, final_truth, targets_truth)
    failures = judge(
        mission, outcome, n_steps, kit.epsilon_px, final_truth, final_detector, kit.truth_probe is not None,
        wrong,
    )  # fmt: skip
    if error is not None:
        failures.insert(0, f"error: {error}")
    summary = {
        "outcome": outcome.value,
        "message": message,
        "passed": not failures,
        "failures": failures,
        "steps": n_steps,
        "moves": sum(1 for s in steps if s.move is not None),
        "refinement_moves": count_refinements(steps),
        "second_choice_moves": count_second_choices(steps),
        "stop_threshold_px": steps[-1].stop_threshold_px if steps else None,
        "final_offset_px": {"truth": final_truth, "detector": final_detector},
        "wrong_target": wrong is not None,
        "wrong_target_index": wrong,
        "targets_truth_final_px": targets_truth,
        "wall_s": round(wall_s, 3),
        "vehicle_s": round(vehicle_s, 3),
        "vehicle_clock_s": {name: round(value, 3) for name, value in clock.items()},
        "phases_wall_s": phases,
        "truth_extremes": kit.truth_extremes() if kit.truth_extremes is not None else None,
        "error": error,
    }
    if kit.tlog is not None and kit.tlog.recording_error is not None:
        writer.recording_errors.append(f"flight.tlog: {kit.tlog.recording_error}")
    report_start = time.perf_counter()
    final = writer.finish(summary, None if kit.tlog is None else kit.tlog.path)
    phases["report"] = round(time.perf_counter() - report_start, 4)
    return MissionResult(
        name=mission.name,
        planner=kit.planner.name,
        outcome=outcome,
        passed=not failures,
        failures=tuple(failures),
        steps=n_steps,
        moves=summary["moves"],
        epsilon_px=kit.epsilon_px,
        final_truth_offset_px=final_truth,
        final_detector_offset_px=final_detector,
        wall_s=wall_s,
        vehicle_s=vehicle_s,
        overhead_ms_mean=final["timing"]["overhead_ms_mean"],
        report_dir=str(writer.out_dir),
        error=error,
        tags=mission.tags,
        info=kit.info,
        refinement_moves=summary["refinement_moves"],
        second_choice_moves=summary["second_choice_moves"],
        vehicle_clock_s=summary["vehicle_clock_s"],
        files=final["files"],
        truth_extremes=summary["truth_extremes"],
        wrong_target=wrong is not None,
        recording_errors=tuple(final["recording_errors"]),
        report_written=final["report_written"],
        phases_s=phases,
    )


@contextmanager
def open_kit(
    mission: Mission,
    out_dir: Path,
    limits: SafetyLimits | None = None,
    models: LoadedModels | None = None,
    signing_key: SigningKey | None = None,
) -> Iterator[FlightKit]:
    """The mission's components, closed (vehicle, camera, sim subprocess) when the block ends.

    `signing_key`: a real vehicle's MAVLink signing key; a vehicle the run starts gets its own (the
    sim-vehicle), or has none (PX4 v1.15), so a key given for one is refused."""
    if signing_key is not None and not mission.is_real:
        raise ValueError(
            f"a signing key is for a real vehicle set up with it; {mission.vehicle} gets a key of its own "
            "per run (sim-mavlink) or cannot sign (px4-sitl: PX4 v1.15 has no signing)"
        )
    with ExitStack() as stack:
        if mission.vehicle == SIM:
            from controller.missions.kits.sim import open_sim_kit

            yield stack.enter_context(open_sim_kit(mission, limits, models))
        elif mission.vehicle == SIM_MAVLINK:
            from controller.missions.kits.sim_mavlink import open_sim_mavlink_kit

            yield stack.enter_context(open_sim_mavlink_kit(mission, out_dir, models, limits))
        elif mission.vehicle == PX4_SITL:
            from controller.missions.kits.px4_sitl import open_px4_sitl_kit

            yield stack.enter_context(open_px4_sitl_kit(mission, out_dir, models, limits))
        elif mission.vehicle == ARDUPILOT_SITL:
            from controller.missions.kits.ardupilot_sitl import open_ardupilot_sitl_kit

            yield stack.enter_context(open_ardupilot_sitl_kit(mission, out_dir, models))
        else:
            from controller.missions.kits.real import open_real_kit

            yield stack.enter_context(open_real_kit(mission, out_dir, models, signing_key))


def run_mission(
    mission: Mission,
    out_dir: str | Path,
    limits: SafetyLimits | None = None,
    media: bool = True,
    models: LoadedModels | None = None,
    rerun_path: str | Path | None = None,
    claimed: bool = False,
    signing_key: SigningKey | None = None,
) -> MissionResult:
    """Build the mission's kit, fly it and write the report folder `out_dir` (`media`: plot and GIF too).

    `out_dir` must not exist or be empty: a report is never written over another
    (`drone_inspect_core.files.OutputDirError`; `claimed`: the caller already claimed it). A mission that
    cannot
    start (a bad checkpoint, a camera that does not open, a simulator that fails) still leaves a
    report saying why, then raises. `signing_key`: a real vehicle's MAVLink signing key (`open_kit`).
    """
    out_dir = Path(out_dir) if claimed else claim_report_dir(out_dir)
    hold_reserve(out_dir)  # room for the outcome, before the flight's .tlog can fill the disk
    try:
        if rerun_path is not None:  # before anything starts: a recording is never overwritten
            from controller.missions.rerun_log import check_rerun_path

            rerun_path = check_rerun_path(rerun_path)
        started = time.perf_counter()
        with open_kit(mission, out_dir, limits, models, signing_key) as kit:
            opened = time.perf_counter()
            result = fly_kit(kit, mission, out_dir, limits, media, rerun_path)
            closing = time.perf_counter()
        phases = {"start": opened - started, **result.phases_s, "close": time.perf_counter() - closing}
        return replace(result, phases_s={name: round(value, 4) for name, value in phases.items()})
    except BaseException as exc:
        if not (out_dir / REPORT_JSON).exists():  # it failed before the flight's own report began
            write_setup_failure(out_dir, mission, exc)
        raise
