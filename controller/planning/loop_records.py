"""The centring loop's records and settings: its configuration, each step, the result, the move schedule.

Plain data (and the move-length schedule), shared by the loop (`controller.planning.loop`),
the report and the missions layer; the loop's behaviour is documented there.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from enum import Enum

from pydantic import BaseModel, ConfigDict, Field, model_validator

from controller.planning.actions import Action
from controller.planning.grounding import TargetQuery
from drone_inspect_core.vocabulary import Vocabulary
from flight.moves import MoveResult
from flight.types import Telemetry
from perception.types import Detection, Frame

TruthProbe = Callable[[], "tuple[float, float] | None"]
"""Judging only: the true (du, dv) of the target centre in pixels now, None when out of view."""


class Outcome(str, Enum):
    """How a centring run (or the mission around it) ended: the one outcome type of the loop, the
    mission file's `expect.outcome`, reports and results. Its value is what files and JSON hold."""

    CENTRED = "centred"
    MAX_STEPS = "max_steps"
    TIMEOUT = "timeout"
    TARGET_LOST = "target_lost"
    TARGET_NOT_FOUND = "target_not_found"  # the named target was never found in this run
    PLANNER_STALLED = "planner_stalled"
    ABORTED = "aborted"  # an exception or Ctrl-C ended the flight (set by the caller)
    STOPPED = "stopped"  # the operator stopped it (Hold, Land, Kill) and the vehicle held (set by the caller)
    ERROR = "error"  # the mission could not start (set by the caller)

    def __str__(self) -> str:
        return self.value


class LoopSettings(BaseModel):
    """How the loop moves and waits: the settings a mission file's `loop:` section sets (this type is
    that section: one declaration for the file and the loop). Lengths in metres, times in seconds."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    move_m: float = Field(default=0.3, gt=0.0, le=2.0)
    """Fixed scheme: the first move's length on an axis."""
    min_move_m: float = Field(default=0.05, gt=0.0, le=2.0)
    shrink: float = Field(default=0.5, gt=0.0, le=1.0)
    """A reversal of direction on an axis multiplies its length (or cap) by this."""
    speed_m_s: float = Field(default=0.5, gt=0.0, le=2.0)
    settle_s: float = Field(default=0.3, ge=0.0, le=5.0)
    settle_speed_m_s: float = Field(default=0.08, gt=0.0, le=1.0)
    settle_timeout_s: float = Field(default=4.0, gt=0.0, le=60.0)
    frame_timeout_s: float = Field(default=5.0, gt=0.0, le=60.0)
    max_stalls: int = Field(default=3, ge=1, le=20)
    lost_rereads: int = Field(default=2, ge=0, le=50)
    lost_recoveries: int = Field(default=1, ge=0, le=5)
    not_found_rereads: int = Field(default=3, ge=0, le=50)
    """Frames re-read, holding, while the named target has not been seen yet, before `target_not_found`."""
    max_refinements: int = Field(default=4, ge=0, le=20)
    """Boundary refinement moves allowed per run (0: none; see the module docstring of planning.loop)."""
    max_second_choices: int = Field(default=4, ge=0, le=20)
    """Moves per run flown on the planner's best-ranked move after it chose "no move" far from centre
    (0: never; such a choice is then a stall; see the module docstring of planning.loop)."""
    colour_reads: int = Field(default=2, ge=1, le=10)
    """Reads in a row that must show a target asked for by its colour, near one place, before it is
    found (1: the first read; see the module docstring of planning.loop)."""
    confirm_with_planner: bool = True
    """Take a detection for the named target only if a planner that judges presence (a calibrated latent
    checkpoint) does not say its kind is out of view; False: the detector alone decides."""
    paint_over_twins: bool = True
    """Show the planner the frame with the other detections of the named target's kind painted over
    (`perception.masking`): the detector's colour reading, not the planner's, tells twins apart."""
    scale_moves: bool = True
    """Scale each move with the detector's pixel offset (True) or the paper's fixed lengths (False)."""
    max_move_m: float = Field(default=1.0, gt=0.0, le=3.0)
    """Scaled scheme: the longest move on an axis (the cap, which shrinks on reversals)."""
    move_gain: float = Field(default=0.8, gt=0.0, le=2.0)
    assumed_distance_m: float = Field(default=2.0, gt=0.0, le=20.0)
    """Scaled scheme: the distance to the wall assumed to turn pixels into metres (not measured)."""
    hfov_deg: float = Field(default=60.0, gt=0.0, lt=180.0)
    """Scaled scheme: the camera's horizontal field of view (the sim camera's; a real one's calibration)."""

    @model_validator(mode="after")
    def _move_lengths(self) -> LoopSettings:
        if not self.min_move_m <= self.move_m:
            raise ValueError(f"need min_move_m <= move_m, got {self.min_move_m} and {self.move_m}")
        if not self.min_move_m <= self.max_move_m:
            raise ValueError(f"need min_move_m <= max_move_m, got {self.min_move_m} and {self.max_move_m}")
        return self


class CentringConfig(LoopSettings):
    """Everything one run of the loop needs besides its components: the settings, and this run's ε,
    words, target and limits."""

    model_config = ConfigDict(extra="forbid", frozen=True, arbitrary_types_allowed=True)

    epsilon_px: float = Field(gt=0.0)
    instruction: str = "center the gauge"
    target: TargetQuery | None = None
    """The target to centre among those detected; None: `parse_instruction(instruction, vocabulary)`."""
    vocabulary: Vocabulary | None = None
    """The words of this run (a mission's own kinds, a site glossary); None: the shipped vocabulary."""
    max_steps: int = Field(default=20, ge=1)
    timeout_s: float = Field(default=120.0, gt=0.0)
    fresh_frame_s: float = Field(default=0.0, ge=0.0)
    """> 0: observe only a frame that shows the scene as it was when the observation began (a stream's
    render, encoding and transport show the vehicle as it was a little earlier, which a vehicle faster
    than real time makes k times longer on its clock): one stamped with its scene's time at or after
    then, or from a camera that stamps nothing, one that arrived this long (wall clock) after
    (`perception.fresh_frame`). 0: the newest frame since the last read."""
    stop_margin_px: float | None = Field(default=None, ge=0.0)
    """Stop when the detector's offset is within ε − this on both axes; None: `default_stop_margin_px(W)`."""

    @model_validator(mode="after")
    def _margin_inside_epsilon(self) -> CentringConfig:
        if self.stop_margin_px is not None and not self.stop_margin_px < self.epsilon_px:
            raise ValueError(
                f"stop_margin_px must be in [0, epsilon_px={self.epsilon_px:g}), got {self.stop_margin_px}"
            )
        return self


class MoveSchedule:
    """Per-axis move lengths (or caps) that shrink when the direction on that axis reverses."""

    def __init__(self, move_m: float, min_move_m: float, shrink: float) -> None:
        self.min_move_m = min_move_m
        self.shrink = shrink
        self.length_m = [move_m, move_m]  # [right/left, up/down]
        self._last_sign = [0, 0]

    def lengths_for(self, action: Action, wanted_m: tuple[float, float] | None = None) -> tuple[float, float]:
        """(right_m, up_m) signed lengths of the move for `action`, updating the schedule.

        `wanted_m` (scaled scheme): per axis, the unsigned length asked for, clamped to
        [min_move_m, the axis's current length]. None (fixed scheme): the axis's current length.
        """
        signs = action.direction()
        out = [0.0, 0.0]
        for axis, sign in enumerate(signs):
            if sign == 0:
                continue
            if self._last_sign[axis] == -sign:
                self.shrink_axis(axis)
            self._last_sign[axis] = sign
            length = self.length_m[axis]
            if wanted_m is not None:
                length = min(length, max(self.min_move_m, wanted_m[axis]))
            out[axis] = sign * length
        return out[0], out[1]

    def shrink_axis(self, axis: int) -> None:
        self.length_m[axis] = max(self.min_move_m, self.length_m[axis] * self.shrink)


class StepEvent(str, Enum):
    """What happened at a step besides a plain planner move (its value is what reports hold)."""

    MOVE = ""
    CENTRED = "centred"
    LOST = "lost"
    NOT_FOUND = "not_found"
    NOT_IN_VIEW = "not_in_view"
    """The detector saw the named kind and colour; the planner said the asked-for target is not in view."""
    COLOUR_CHECK = "colour_check"
    """The detector saw the named kind in the colour asked for, on fewer reads in a row than `colour_reads`:
    the loop holds and reads again before it takes it (a not-found read)."""
    RECOVERY = "recovery"
    REFINEMENT = "refinement"
    SECOND_CHOICE = "second_choice"
    STALL = "stall"
    MAX_STEPS = "max_steps"
    TIMEOUT = "timeout"

    def __str__(self) -> str:
        return self.value


@dataclass(frozen=True)
class StepTiming:
    """Wall-clock seconds spent in each part of a step; `overhead_s` is everything but the move."""

    read_s: float
    detect_s: float
    plan_s: float
    move_s: float
    total_s: float

    @property
    def overhead_s(self) -> float:
        return self.total_s - self.move_s


@dataclass
class StepRecord:
    """One step of the loop: what was seen, what was decided, what was flown."""

    index: int
    frame: Frame
    detection: Detection | None  # the named target's detection (`CentringConfig.target`), None: not seen
    offset_px: tuple[float, float] | None
    truth_offset_px: tuple[float, float] | None
    centred: bool
    telemetry: Telemetry
    vehicle_time_s: float
    action: Action | None = None
    distances: tuple[float, ...] | None = None
    move_m: tuple[float, float] | None = None  # commanded (right_m, up_m)
    move: MoveResult | None = None
    event: StepEvent = StepEvent.MOVE
    stop_threshold_px: float | None = None  # ε − the stopping margin: what `centred` was tested against
    detections: tuple[Detection, ...] = ()  # everything the detector saw, strongest first
    presence: float | None = None  # the planner's p(asked-for target in view) on this frame, where asked
    timing: StepTiming = field(default_factory=lambda: StepTiming(0.0, 0.0, 0.0, 0.0, 0.0))


@dataclass
class CentringResult:
    outcome: Outcome
    steps: list[StepRecord]
    message: str = ""

    @property
    def moves(self) -> int:
        """How many moves were flown (planner, refinement and recovery moves)."""
        return sum(1 for s in self.steps if s.move is not None)

    @property
    def refinement_moves(self) -> int:
        """Boundary refinement moves: flown by the loop after the planner chose "no move"."""
        return count_refinements(self.steps)

    @property
    def second_choice_moves(self) -> int:
        """Moves flown on the planner's best-ranked move after it chose "no move" far from centre."""
        return count_second_choices(self.steps)


def count_second_choices(steps: list[StepRecord]) -> int:
    """How many moves `steps` flew on the planner's second choice (after a "no move" far from centre)."""
    return sum(1 for s in steps if s.event is StepEvent.SECOND_CHOICE)


def count_not_in_view(steps: list[StepRecord]) -> int:
    """Frames on which the detector saw the named target and the planner said it was not in view."""
    return sum(1 for s in steps if s.event is StepEvent.NOT_IN_VIEW)


def count_refinements(steps: list[StepRecord]) -> int:
    """How many boundary refinement moves `steps` contain."""
    return sum(1 for s in steps if s.event is StepEvent.REFINEMENT)
