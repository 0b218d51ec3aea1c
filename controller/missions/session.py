"""A flight session: one take-off, any number of centring instructions, one landing, one report folder.

`FlightSession(mission, out_dir)` is a context manager. On entry it opens the mission's kit
(`controller.missions.kits.open_kit`: vehicle, camera, detector, planner, a simulator's truth; or takes
a kit already open, `kit=`), puts the vehicle behind the safety limits (`SafeVehicle`), checks ε and
understands every instruction the mission gives (a refused one raises before anything is touched), and
starts `report.json`. On exit a vehicle still in the air is held, landed and disarmed
(`flight.safety.safe_stop`), the report is finished (`result`: the flight's `MissionResult`) and a kit
the session opened is closed. In between, one operation at a time, each in the caller's thread:

- `connect()`: open the link (done by `take_off` when not yet).
- `take_off()`: ready, arm, take off to the start (a simulator: place the drone at the mission's start
  pose), hover, offboard with a zero setpoint. Again after a `land()`; never after a `kill()`.
- `centre(instruction, on_step=None, stop=None)`: understand the instruction (one the vocabulary cannot
  act on raises `InstructionRefused` before anything moves), point the simulator's truth at the target
  it names, run the centring loop (`CentringLoop`: its own step budget and timeout), judge it, record
  it in report.json; return its `InstructionResult`. The vehicle holds when it ends, whatever the
  outcome (`target_not_found` too: the next instruction flies from there).
- `fly()`: the mission's whole flight: take off, centre each of its instructions in turn, land
  (`controller.missions.runner.fly_kit` is this).

Interrupts, from any thread, whatever runs: `hold()` (the running operation stops, a centring with
outcome `stopped`; the vehicle holds in the autopilot's own hold mode, leaving offboard; the next
`centre` re-enters it), `land()` (stop, land, disarm) and `kill()` (stop the motors at once: a flying
vehicle falls). A `stop` event given to `centre` stops it the same way, the vehicle holding in offboard.
How a stop reaches a running operation: `controller.missions.interrupts`. On a real-time vehicle
(MAVLink) an interrupt commands the vehicle at once from its own thread; on a simulated-clock vehicle
(the in-process sim: nothing moves between its calls, and PyBullet wants one thread) the running
operation stops at its next vehicle call, before any simulated time passes, and the interrupt acts
then, from its thread. Read the state with `phase` and `telemetry()` (safe from any thread).

Safety, as in every flight here: every vehicle command goes through `SafeVehicle` (speed limits,
geofence, setpoint watchdog); every wait has a timeout; an error or Ctrl-C (SIGINT/SIGTERM raise
`KeyboardInterrupt` in the main thread, `flight.signals`) in an operation holds, leaves offboard, lands
and disarms (`safe_stop`) and is re-raised (`fly()` records an error and returns; Ctrl-C propagates);
the report is rewritten after every step; a recording (Rerun, a caller's `on_step`) that fails is said
in the report and stops, never the flight.
"""

from __future__ import annotations

import contextlib
import logging
import math
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import ExitStack, contextmanager
from dataclasses import replace
from enum import Enum
from pathlib import Path
from types import TracebackType
from typing import Any

from controller.missions.flight_results import finish_flight, judge_instruction
from controller.missions.interrupts import OperatorStop, StoppableVehicle
from controller.missions.kits import open_kit
from controller.missions.kits.base import FlightKit, LoadedModels
from controller.missions.loop_setup import epsilon_for, loop_config, mission_vocabulary
from controller.missions.report import ReportWriter
from controller.missions.results import InstructionResult, MissionResult
from controller.missions.schema import Mission, MissionInstruction
from controller.planning.grounding import TargetQuery, understand
from controller.planning.loop import CentringLoop
from controller.planning.loop_records import CentringConfig, Outcome, StepRecord
from drone_inspect_core.frames import world_ned_to_heading
from drone_inspect_core.signing import SigningKey
from flight.moves import Milestones, fly_offset, take_off_to_start
from flight.safe_vehicle import SafeVehicle
from flight.safety import SafetyLimits, safe_stop
from flight.signals import StopRequested
from flight.types import PositionNed, Telemetry, VelocityBody

log = logging.getLogger(__name__)

INTERRUPT_WAIT_S = 30.0
"""How long an interrupt on a simulated-clock vehicle waits for the running operation to stop (it stops
at its next vehicle call; a camera read or a detection can delay that a little)."""

StepCallback = Callable[[StepRecord], None]


class Phase(str, Enum):
    """Where a session's vehicle is (its value is what reports and a console show)."""

    ON_GROUND = "on_ground"
    TAKING_OFF = "taking_off"
    HOLDING = "holding"
    CENTRING = "centring"
    LANDING = "landing"
    LANDED = "landed"
    KILLED = "killed"

    def __str__(self) -> str:
        return self.value


class SessionError(RuntimeError):
    """An operation the session cannot do now: another one runs, or the vehicle is not where it must be
    (centre before take-off, take off after a kill, anything after the session closed)."""


class FlightSession:
    """One flight of a mission's vehicle, any number of instructions (see the module docstring)."""

    def __init__(
        self,
        mission: Mission,
        out_dir: str | Path,
        *,
        kit: FlightKit | None = None,
        limits: SafetyLimits | None = None,
        models: LoadedModels | None = None,
        signing_key: SigningKey | None = None,
        media: bool = True,
        rerun_path: Path | None = None,
    ) -> None:
        """`kit`: one already open (the caller closes it); None: the session opens the mission's own
        (`models`: loaded ones to share; `signing_key`: a real vehicle's). `media`: the plot and the GIF
        too; `rerun_path`: also record the flight to this new .rrd file."""
        self.mission = mission
        self.out_dir = Path(out_dir)
        self.limits = limits
        self.media = media
        self.rerun_path = rerun_path
        self._given_kit = kit
        self._models = models
        self._signing_key = signing_key
        self._stack = ExitStack()
        self._op_lock = threading.Lock()  # one operation at a time
        self._interrupt_lock = threading.Lock()  # one interrupt at a time
        self._command_lock = threading.RLock()  # an operation's velocity commands against an interrupt's
        self._stop = threading.Event()
        self._interrupt: str | None = None  # the session's interrupt that stopped the running operation
        self._phase = Phase.ON_GROUND
        self._offboard = False
        self._connected = False
        self._closed = False
        self._results: list[InstructionResult] = []
        self.flown_entries: list[MissionInstruction] = []
        """The entry each result was flown for (its `expect`), in order."""
        self.flying_the_plan = False
        """`fly()` flies the mission's instructions: one it did not reach counts as not flown."""
        self._errors: list[str] = []
        self._clock = Milestones()
        """Milestones on the vehicle's clock, each also on the wall clock (the phases of `phases_s`)."""
        self.kit_open_s = 0.0
        """Wall seconds the kit took to open (a simulator started, MAVSDK and the camera opened)."""
        self.vehicle_start_s: float | None = None  # vehicle clock, after the first take-off
        self.vehicle_end_s: float | None = None  # vehicle clock, when the last centring ended
        self.start_position: PositionNed | None = None
        """Where the first take-off left the vehicle (local NED): where `return_to_start` looks again."""
        self._last_telemetry: Telemetry | None = None
        self._wall_start = time.perf_counter()
        self.result: MissionResult | None = None
        """The flight's result, once the session has closed."""

    # ------------------------------------------------------------------ opening and closing
    def __enter__(self) -> FlightSession:
        self._wall_start = time.perf_counter()
        try:
            kit = self._given_kit or self._stack.enter_context(
                open_kit(self.mission, self.out_dir, self.limits, self._models, self._signing_key)
            )
            self.kit_open_s = time.perf_counter() - self._wall_start
            self._clock = Milestones()  # the flight's wall times count from here
            self.kit = replace(kit, epsilon_px=epsilon_for(self.mission, kit))  # ε resolved once, here
            # A kit may bring its vehicle already behind the safety limits (the in-process sim does).
            safe = (
                kit.vehicle if isinstance(kit.vehicle, SafeVehicle) else SafeVehicle(kit.vehicle, self.limits)
            )
            self._safe = safe
            self.vocabulary = mission_vocabulary(self.mission)
            self.planned = self._plan()  # every instruction understood, and ε checked, before anything flies
            self.writer = ReportWriter(self.out_dir, self._header(), self.epsilon_px, media=self.media)
            self.recorder = self._open_recorder()
            self._record_rerun = (
                None
                if self.recorder is None
                else self._guarded(self.recorder.add_step, "the Rerun recording")
            )
        except BaseException:
            self._stack.close()
            raise
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        try:
            if exc is not None and not isinstance(exc, OperatorStop):
                self._record_error(exc)
            if self._phase in (Phase.TAKING_OFF, Phase.HOLDING, Phase.CENTRING, Phase.LANDING):
                self._interrupt = "close"
                self._stop.set()  # an operation of another thread stops at its next vehicle call
                idle = self._op_lock.acquire(timeout=INTERRUPT_WAIT_S)
                try:
                    if idle or self._safe.realtime:
                        self._safe_stop()
                        self._phase, self._offboard = Phase.LANDED, False
                finally:
                    if idle:
                        self._op_lock.release()
        finally:
            self._closed = True
            try:
                self.result = finish_flight(self)
            finally:
                closing = time.perf_counter()
                self._stack.close()
                if self.result is not None:  # the phases before and after the flight (`phases`)
                    phases = {"start": self.kit_open_s, **self.result.phases_s}
                    phases["close"] = time.perf_counter() - closing
                    self.result = replace(self.result, phases_s={k: round(v, 4) for k, v in phases.items()})

    def _plan(self) -> list[tuple[MissionInstruction, TargetQuery]]:
        """The mission's instructions with what each names (the scene's resolved one where it gives none);
        `InstructionRefused` for one the vocabulary cannot act on, ValueError for an ε inside the margin."""
        kit = self.kit
        if self.mission.instructions:
            planned = [(e, understand(e.instruction, self.vocabulary)) for e in self.mission.instructions]
        else:
            entry = MissionInstruction(instruction=kit.instruction)
            planned = [(entry, kit.target or understand(kit.instruction, self.vocabulary))]
        config = loop_config(
            self.mission, self.epsilon_px, planned[0][0].instruction, planned[0][1], self.vocabulary
        )
        CentringLoop(self._safe, kit.camera, kit.detector, kit.planner, config).stop_threshold_px(
            kit.image_width_px
        )
        return planned

    def _header(self) -> dict[str, Any]:
        return {
            "mission": self.mission.name,
            "tags": list(self.mission.tags),
            "planner": self.kit.planner.name,
            "epsilon_px": self.epsilon_px,
            "instructions_planned": [entry.instruction for entry, _ in self.planned],
            "vehicle": self.mission.vehicle,
            "camera": self.mission.camera,
            "setup": self.kit.info,
            "mission_file": self.mission.model_dump(mode="json"),
        }

    def _open_recorder(self) -> Any:
        if self.rerun_path is None:
            return None
        from controller.missions.rerun_log import RerunRecorder

        return RerunRecorder(self.rerun_path, self.epsilon_px, self._header())

    # ------------------------------------------------------------------ what a caller reads
    @property
    def vehicle(self) -> SafeVehicle:
        """The vehicle behind the safety limits (on a simulated clock: touch it only between operations)."""
        return self._safe

    @property
    def camera(self) -> Any:
        return self.kit.camera

    @property
    def detector(self) -> Any:
        return self.kit.detector

    @property
    def planner(self) -> Any:
        return self.kit.planner

    @property
    def epsilon_px(self) -> float:
        assert self.kit.epsilon_px is not None
        return self.kit.epsilon_px

    @property
    def phase(self) -> Phase:
        return self._phase

    @property
    def results(self) -> list[InstructionResult]:
        """Every instruction centred so far, in order."""
        return list(self._results)

    @property
    def errors(self) -> list[str]:
        """The errors that ended operations (each also in the report)."""
        return list(self._errors)

    @property
    def vehicle_clock_s(self) -> dict[str, float]:
        """Milestones on the vehicle's clock: connected_s, ready_s, offboard_s (the first take-off's),
        loop_end_s (the last centring's end), landed_s (the last landing's)."""
        return dict(self._clock)

    @property
    def milestones_wall_s(self) -> dict[str, float]:
        """The same milestones on the wall clock, in seconds since the kit was open."""
        return dict(self._clock.wall_s)

    @property
    def wall_s(self) -> float:
        """Wall-clock seconds since the session opened."""
        return time.perf_counter() - self._wall_start

    def telemetry(self) -> Telemetry | None:
        """The vehicle's state now (a real-time vehicle), or as last seen by an operation (a simulated-clock
        vehicle while one runs: it may not be touched from another thread); None before any."""
        if self._safe.realtime or not self._op_lock.locked():
            try:
                self._last_telemetry = self._safe.telemetry()
            except Exception as exc:  # a lost link: said by the operation that meets it
                log.debug("no telemetry: %s", exc)
        return self._last_telemetry

    def understand(self, instruction: str) -> TargetQuery:
        """What `instruction` names, or `InstructionRefused` (naming the word and the closest known)."""
        return understand(instruction, self.vocabulary)

    # ------------------------------------------------------------------ operations
    @contextmanager
    def _operation(
        self, name: str, allowed: Sequence[Phase], stop: threading.Event | None = None
    ) -> Iterator[StoppableVehicle]:
        """Run one operation in this thread: refused while another runs or from the wrong phase."""
        if self._closed:
            raise SessionError(f"{name}: the session is closed")
        if not self._op_lock.acquire(blocking=False):
            raise SessionError(f"{name}: another operation is running (hold, land or kill interrupt it)")
        try:
            if self._phase not in allowed:
                wanted = " or ".join(p.value for p in allowed)
                raise SessionError(f"{name}: the vehicle is {self._phase.value}, not {wanted}")
            self._stop.clear()
            self._interrupt = None
            stops = [self._stop] if stop is None else [self._stop, stop]
            yield StoppableVehicle(self._safe, stops, self._command_lock)
        finally:
            self._op_lock.release()

    def connect(self) -> None:
        """Open the link to the vehicle (bounded by the limits' connect timeout); idempotent."""
        if self._connected:
            return
        self._safe.connect()
        self._connected = True
        if "connected_s" not in self._clock:
            self._clock["connected_s"] = self._safe.time_s()

    def take_off(self) -> None:
        """Connect, ready, arm, take off to the start and hover in offboard (see the module docstring)."""
        with self._operation("take off", (Phase.ON_GROUND, Phase.LANDED)) as vehicle:
            try:
                self.connect()
            except BaseException as exc:  # nothing flies yet: said, nothing to land
                self._record_error(exc)
                raise
            self._phase = Phase.TAKING_OFF
            try:
                altitude_m = self.kit.takeoff_altitude_m or self.mission.takeoff_altitude_m
                # The first take-off's milestones are the flight's; a later one's are not kept.
                clock = self._clock if "offboard_s" not in self._clock else {}
                take_off_to_start(vehicle, altitude_m, self.kit.place_at_start, clock)
                self._offboard = True
                if self.vehicle_start_s is None:
                    self.vehicle_start_s = self._safe.time_s()
                    self.start_position = self._safe.telemetry().position_ned
                if self._interrupt is None:
                    self._phase = Phase.HOLDING
            except BaseException as exc:
                if not self._stopped_by_operator(exc, vehicle):
                    self._abort(exc)
                    raise

    def centre(
        self,
        instruction: str | MissionInstruction,
        *,
        on_step: StepCallback | None = None,
        stop: threading.Event | None = None,
        target: TargetQuery | None = None,
    ) -> InstructionResult:
        """Centre the target `instruction` names, from where the vehicle holds (see the module docstring).

        `on_step` gets each `StepRecord` as it happens (one that raises is said once and dropped, never
        the flight); `stop`: set it from another thread to stop the loop promptly, the vehicle holding
        (outcome `stopped`); `target`: what the loop centres when the caller knows better than the words
        (a scene's resolved instruction). A mapping entry's `expect` judges it (else the mission's)."""
        entry = (
            instruction
            if isinstance(instruction, MissionInstruction)
            else MissionInstruction(instruction=instruction)
        )
        query = target or self.understand(entry.instruction)  # refused here: nothing has moved
        config = loop_config(self.mission, self.epsilon_px, entry.instruction, query, self.vocabulary)
        with self._operation("centre", (Phase.HOLDING,), stop) as vehicle:
            return self._centre(vehicle, entry, query, config, on_step)

    def _centre(
        self,
        vehicle: StoppableVehicle,
        entry: MissionInstruction,
        query: TargetQuery,
        config: CentringConfig,
        on_step: StepCallback | None,
    ) -> InstructionResult:
        kit, index = self.kit, len(self._results) + 1
        if kit.aim_truth is not None:
            kit.aim_truth(query)  # judging only: the truth of the target this instruction names
        expect = entry.expect or self.mission.expect
        self.writer.begin_instruction(
            {
                "index": index,
                "instruction": entry.instruction,
                "target": {"kind": query.kind, "attribute": query.attribute},
                "expect": expect.model_dump(mode="json"),
            }
        )
        if self.recorder is not None:
            try:
                self.recorder.begin_instruction(index, entry.instruction)
            except Exception as exc:  # the recording is an extra: said, never the flight
                self.writer.recording_errors.append(f"the Rerun recording: {exc}")
        loop = CentringLoop(
            vehicle, kit.camera, kit.detector, kit.planner, config, truth_probe=kit.truth_probe
        )
        loop.on_step = self._step_callback(on_step)
        self._phase = Phase.CENTRING
        wall_start, vehicle_start_s = time.perf_counter(), self._safe.time_s()
        outcome, message, error, returned = Outcome.ABORTED, "", None, False
        try:
            if not self._offboard:  # after an operator's hold: back into offboard from a zero setpoint
                vehicle.set_velocity_body(VelocityBody())
                vehicle.start_offboard()
                self._offboard = True
            result = loop.run()
            if result.outcome is Outcome.TARGET_NOT_FOUND and self._back_to_start(vehicle, config):
                returned = True
                result = loop.run()  # the same loop, its records going on: look again from the start
            outcome, message = result.outcome, result.message
            if self._interrupt is None:
                self._phase = Phase.HOLDING
        except BaseException as exc:
            if not self._stopped_by_operator(exc, vehicle):
                error = message = self._abort(exc)
                raise
            outcome = Outcome.STOPPED
            message = f"stopped by the operator ({self._interrupt or 'stop'}); the vehicle holds"
        finally:
            self.vehicle_end_s = self._clock["loop_end_s"] = self._safe.time_s()
            judged = judge_instruction(
                self, index, entry, query, loop.steps, outcome, message, error,
                wall_s=time.perf_counter() - wall_start, vehicle_s=self.vehicle_end_s - vehicle_start_s,
                returned_to_start=returned,
            )  # fmt: skip
            self._results.append(judged)
            self.flown_entries.append(entry)
            self.writer.end_instruction(judged.summary())
        return judged

    def _back_to_start(self, vehicle: StoppableVehicle, config: CentringConfig) -> bool:
        """An instruction's target not in view where the vehicle holds: fly back across the wall to where
        the flight started (the pose after take-off; its distance from the wall kept), from where the
        operator's view was set up, to look there (`Mission.return_to_start`). False where it is there
        already, or the mission says not to."""
        start = self.start_position
        if not self.mission.return_to_start or start is None:
            return False
        telemetry = self._safe.telemetry()
        here = telemetry.position_ned
        _, right_m = world_ned_to_heading(
            start.north_m - here.north_m, start.east_m - here.east_m, math.radians(telemetry.attitude.yaw_deg)
        )
        up_m = here.down_m - start.down_m
        if max(abs(right_m), abs(up_m)) < config.min_move_m:
            return False
        log.info(
            "the target is not in view here: back to the start (%.2f m right, %.2f m up) to look again",
            right_m,
            up_m,
        )
        fly_offset(vehicle, right_m, up_m, config.speed_m_s, config.settle_speed_m_s, config.settle_timeout_s)
        return True

    def fly(self, instructions: Sequence[MissionInstruction] | None = None) -> None:
        """The mission's flight: take off, centre each instruction in turn (`instructions`, default the
        mission's), holding in between, then land. An error is recorded (the vehicle was held and
        landed) and ends the flight; the instructions after it are not flown. Ctrl-C propagates."""
        planned = self.planned if instructions is None else [(e, None) for e in instructions]
        self.flying_the_plan = instructions is None
        try:
            self.take_off()
            for entry, query in planned:
                if self._phase is not Phase.HOLDING:
                    break
                self.centre(entry, target=query)
            if self._phase is Phase.HOLDING:
                self.land()
        except Exception as exc:
            log.error("mission %s aborted: %s", self.mission.name, self._errors[-1] if self._errors else exc)
            self._record_error(exc)

    # ------------------------------------------------------------------ interrupts (any thread)
    def hold(self) -> None:
        """Stop whatever runs and hold in the autopilot's hold mode (offboard left); on the ground: none."""
        self._interrupt_with("hold", self._hold_now)

    def land(self) -> None:
        """Stop whatever runs, land and disarm; returns once landed (bounded by the landing timeout)."""
        self._interrupt_with("land", self._land_now)

    def kill(self) -> None:
        """Stop whatever runs and stop the motors at once (forced disarm): a flying vehicle falls. Never
        behind another interrupt: a Kill pressed during a landing acts at once (on a real-time vehicle)."""
        self._interrupt_with("kill", self._kill_now, wait_for_interrupts=False)

    def _interrupt_with(
        self, name: str, action: Callable[[], None], wait_for_interrupts: bool = True
    ) -> None:
        if self._closed:
            raise SessionError(f"{name}: the session is closed")
        with self._interrupt_lock if wait_for_interrupts else contextlib.nullcontext():
            self._interrupt = name
            self._stop.set()
            if self._op_lock.acquire(blocking=False):  # nothing runs: act here
                try:
                    action()
                finally:
                    self._op_lock.release()
            elif self._safe.realtime:  # at once, from this thread; the operation unwinds by itself
                action()
            elif self._op_lock.acquire(timeout=INTERRUPT_WAIT_S):  # it stops at its next vehicle call
                try:
                    action()
                finally:
                    self._op_lock.release()
            else:
                raise SessionError(
                    f"{name}: the running operation did not stop within {INTERRUPT_WAIT_S:g} s"
                )

    def _hold_now(self) -> None:
        if self._phase in (Phase.ON_GROUND, Phase.LANDED, Phase.KILLED):
            return
        with self._command_lock:
            if self._offboard:
                self._safe.stop_offboard()  # PX4: HOLD (Loiter), confirmed from telemetry
                self._offboard = False
            else:
                self._safe.hold()
        self._phase = Phase.HOLDING
        self._last_telemetry = self._safe.telemetry()

    def _land_now(self) -> None:
        if self._phase in (Phase.ON_GROUND, Phase.LANDED, Phase.KILLED):
            return
        self._phase = Phase.LANDING
        try:
            if self._offboard:
                self._safe.stop_offboard()
                self._offboard = False
            self._safe.land()
            self._safe.disarm()
            self._clock["landed_s"] = self._safe.time_s()
        except Exception as exc:  # the landing itself failed: the safe stop's best effort, then say it
            if self._phase is Phase.KILLED:  # a Kill under the landing ended it: nothing left to land
                return
            self._abort(exc)
            raise
        if self._phase is not Phase.KILLED:
            self._phase = Phase.LANDED

    def _kill_now(self) -> None:
        if self._phase is Phase.KILLED:
            return
        self._safe.kill()
        self._phase, self._offboard = Phase.KILLED, False
        log.warning("motors killed by the operator")

    def _stopped_by_operator(self, exc: BaseException, vehicle: StoppableVehicle) -> bool:
        """Whether an operation ended by `exc` was stopped by the operator (`OperatorStop`, or an error
        the interrupt itself caused, such as offboard left under a running move), and if so leave the
        vehicle holding: a caller's `stop` event holds in offboard (zero velocity) here; a session
        interrupt acts by itself (at once, or once this operation has unwound)."""
        if not (isinstance(exc, OperatorStop) or (vehicle.stopped and isinstance(exc, Exception))):
            return False
        if not isinstance(exc, OperatorStop):
            log.info("stopped by the operator (%s: %s)", type(exc).__name__, exc)
        if self._interrupt is None:
            with self._command_lock:
                self._safe.hold()
            self._phase = Phase.HOLDING
        return True

    def _abort(self, exc: BaseException) -> str:
        """An operation failed (an error, Ctrl-C): hold, land and disarm what flies; the error in words."""
        how = self._record_error(exc)
        log.error("flight interrupted (%s): holding, then landing", how)
        aftermath = self._safe_stop()
        if aftermath:
            how = f"{how}; {aftermath}"
            self._errors[-1] = how
        self._phase, self._offboard = Phase.LANDED, False
        return how

    def _safe_stop(self) -> str:
        """`flight.safety.safe_stop` (hold, leave offboard, land if in the air, disarm), never raising: what
        cannot even be asked (a vehicle never connected) is logged."""
        try:
            return safe_stop(self._safe)
        except Exception as exc:
            log.error("safe stop: %s: %s", type(exc).__name__, exc)
            return ""

    def _record_error(self, exc: BaseException) -> str:
        if isinstance(exc, KeyboardInterrupt):
            how = str(exc) if isinstance(exc, StopRequested) else "stopped by Ctrl-C"
            text = f"interrupted ({how}); a vehicle in the air was held, then landed"
        else:
            text = f"{type(exc).__name__}: {exc}"
        if not any(error.startswith(text) for error in self._errors):  # (`_abort` may have added to it)
            self._errors.append(text)
        return text

    # ------------------------------------------------------------------ recording
    def _step_callback(self, on_step: StepCallback | None) -> StepCallback:
        extra = []
        if self._record_rerun is not None:
            extra.append(self._record_rerun)
        if on_step is not None:
            extra.append(self._guarded(on_step, "the step callback"))

        def record(step: StepRecord) -> None:
            self._last_telemetry = step.telemetry
            self.writer.add_step(step)
            for callback in extra:
                callback(step)

        return record

    def _guarded(self, record: Callable[[Any], None], what: str) -> Callable[[Any], None]:
        """`record`, stopped (and said once, in the report too) at its first failure: a recording that
        fails never ends a flight."""
        failed = False

        def call(value: Any) -> None:
            nonlocal failed
            if failed:
                return
            try:
                record(value)
            except Exception as exc:
                failed = True
                self.writer.recording_errors.append(f"{what}: {exc}")
                log.error("%s stopped: %s; the flight goes on", what, exc)

        return call
