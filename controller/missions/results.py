"""Missions: finding mission files, judging a flown mission against its expectations, the result row.

The file format is `controller.missions.schema`; flying one is
`controller.missions.runner`. A mission passes when the loop's outcome is the
expected one and every expectation holds; "centred" is judged by simulator
truth where the mission has it (the detector could be wrong), otherwise by the
detector's final offset.
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import asdict, dataclass, field
from typing import Any

from controller.missions.schema import Expectations, Mission
from controller.planning.loop_records import Outcome, StepEvent, StepRecord


@dataclass(frozen=True)
class MissionResult:
    """One flown mission, as a suite table row and a JSON object."""

    name: str
    planner: str
    outcome: Outcome
    passed: bool
    failures: tuple[str, ...]
    steps: int
    moves: int
    epsilon_px: float
    final_truth_offset_px: tuple[float, float] | None
    final_detector_offset_px: tuple[float, float] | None
    wall_s: float
    vehicle_s: float
    overhead_ms_mean: float | None
    report_dir: str | None = None
    error: str | None = None
    tags: tuple[str, ...] = ()
    refinement_moves: int = 0
    """Boundary refinement moves the loop flew after the planner chose "no move" (see planning.loop)."""
    second_choice_moves: int = 0
    """Moves flown on the planner's best-ranked move after it chose "no move" far from centre."""
    not_in_view_reads: int = 0
    """Frames on which the detector saw the named target and the planner said it was not in view."""
    info: dict[str, Any] = field(default_factory=dict)
    vehicle_clock_s: dict[str, float] = field(default_factory=dict)
    """Milestones (connected, ready, offboard) on the vehicle's clock (PX4 SITL: its simulated time)."""
    files: dict[str, str | None] = field(default_factory=dict)
    """What the report folder holds: report, trajectory, gif, tlog (None: not written)."""
    wrong_target: bool = False
    """The loop ended centred, but per truth another target (not the named one) was within ε."""
    truth_extremes: dict[str, Any] | None = None
    """Simulated MAVLink vehicles: the largest speeds and excursions from home per simulator truth."""
    recording_errors: tuple[str, ...] = ()
    """What could not be written (a full disk, a read-only folder): the flight went on without it."""
    report_written: bool = True
    """Whether report.json holds the final state (False: only the console has the outcome)."""
    phases_s: dict[str, float] = field(default_factory=dict)
    """Wall seconds per phase of the mission (`controller.missions.phases.PHASES`, the loop's parts)."""
    instructions: tuple[dict[str, Any], ...] = ()
    """Each instruction of the flight, in order (`InstructionResult.summary()`: its outcome, steps, moves,
    final offsets, wrong target, judgement). The fields above are the flight's: `outcome` the first
    instruction's that missed its expectation (else the last one's), `steps`/`moves` the sums, the final
    offsets the last instruction's, `wrong_target` any instruction's."""

    @property
    def final_truth_error_px(self) -> float | None:
        """max(|du|, |dv|) of the final truth offset: the number ε is compared with."""
        off = self.final_truth_offset_px
        return None if off is None else max(abs(off[0]), abs(off[1]))

    def to_json(self) -> dict[str, Any]:
        data = asdict(self)
        data["final_truth_error_px"] = self.final_truth_error_px
        return data


def count_steps(steps: list[StepRecord]) -> int:
    """Steps as the budget counts them: planner decisions plus recovery moves."""
    return sum(1 for s in steps if s.action is not None or s.event is StepEvent.RECOVERY)


def wrong_target(
    outcome: Outcome,
    epsilon_px: float,
    final_truth_offset_px: tuple[float, float] | None,
    targets_truth: list[tuple[float, float] | None] | None,
    named: Collection[int] = (0,),
) -> int | None:
    """A wrong-target centring: the loop ended `centred`, the named target is not within ε per truth,
    and another target is. Returns that target's index in the scene, else None.

    `targets_truth`: every target's true offset at the end (None: no such truth, e.g. a real vehicle);
    `named`: the indices of the targets the instruction names (the scene's named one, 0, by default),
    which are not candidates (`final_truth_offset_px` judges the named one, as for success)."""
    if outcome is not Outcome.CENTRED or not targets_truth:
        return None
    if final_truth_offset_px is not None and _error_px(final_truth_offset_px) <= epsilon_px:
        return None
    for index, offset in enumerate(targets_truth):
        if index not in named and offset is not None and _error_px(offset) <= epsilon_px:
            return index
    return None


def _error_px(offset: tuple[float, float]) -> float:
    return max(abs(offset[0]), abs(offset[1]))


def judge(
    mission: Mission,
    outcome: Outcome,
    steps: int,
    epsilon_px: float,
    final_truth_offset_px: tuple[float, float] | None,
    final_detector_offset_px: tuple[float, float] | None,
    has_truth: bool,
    wrong_target_index: int | None = None,
    expect: Expectations | None = None,
) -> list[str]:
    """Every expectation that the flight broke, in words; empty when it passed. `expect`: an
    instruction's own expectations (None: the mission's). `wrong_target_index`: see `wrong_target` (a
    wrong-target centring never passes)."""
    expect = expect or mission.expect
    failures: list[str] = []
    if wrong_target_index is not None:
        failures.append(
            f"wrong target centred: target {wrong_target_index} is within ε per truth, not the named one"
        )
    if outcome is not expect.outcome:
        failures.append(f"outcome {outcome}, expected {expect.outcome}")
    final = final_truth_offset_px if has_truth else final_detector_offset_px
    source = "truth" if has_truth else "detector"
    error_px = None if final is None else max(abs(final[0]), abs(final[1]))
    if expect.outcome is Outcome.CENTRED:
        if error_px is None:
            failures.append(f"target not in view at the end per {source}")
        elif error_px > epsilon_px:
            failures.append(f"final offset {error_px:.1f} px per {source} > ε {epsilon_px:g} px")
    if expect.max_steps is not None and steps > expect.max_steps:
        failures.append(f"{steps} steps > the expected at most {expect.max_steps}")
    if expect.final_offset_px is not None and (error_px is None or error_px > expect.final_offset_px):
        shown = "none" if error_px is None else f"{error_px:.1f} px"
        failures.append(f"final offset {shown} per {source} > {expect.final_offset_px:g} px")
    return failures


@dataclass(frozen=True)
class InstructionResult:
    """One instruction of a flight (`controller.missions.session`): what it asked, how its centring loop
    ended, and how it was judged against its expectations."""

    index: int
    """1, 2, ...: its place in the flight."""
    instruction: str
    target: dict[str, str | None]
    """What the loop centred: {"kind", "attribute"} as the instruction was understood (None: not named)."""
    outcome: Outcome
    message: str
    passed: bool
    failures: tuple[str, ...]
    steps: int
    """Steps as the budget counts them (`count_steps`)."""
    moves: int
    refinement_moves: int
    second_choice_moves: int
    final_truth_offset_px: tuple[float, float] | None
    final_detector_offset_px: tuple[float, float] | None
    wrong_target_index: int | None
    """Per truth, another target (its index in the scene) within ε where the loop stopped (`wrong_target`)."""
    targets_truth_final_px: list[tuple[float, float] | None] | None
    """Every target's true offset when the loop ended (the scene's named target first); None: no truth."""
    vehicle_s: float
    wall_s: float
    error: str | None = None
    returned_to_start: bool = False
    """Its target was not in view where the vehicle held, and it flew back to the start to look again."""
    not_in_view_reads: int = 0
    """Frames on which the detector saw the named target and the planner said it was not in view."""
    records: tuple[StepRecord, ...] = field(default=(), repr=False, compare=False)
    """The loop's step records (frames included): for a caller's own use; not in `summary()`."""

    @property
    def wrong_target(self) -> bool:
        return self.wrong_target_index is not None

    @property
    def final_truth_error_px(self) -> float | None:
        off = self.final_truth_offset_px
        return None if off is None else _error_px(off)

    def summary(self) -> dict[str, Any]:
        """JSON-able, without the step records: what report.json and `MissionResult.instructions` hold."""
        data = {f: getattr(self, f) for f in self.__dataclass_fields__ if f != "records"}
        data["outcome"] = self.outcome.value
        data["wrong_target"] = self.wrong_target
        data["final_truth_error_px"] = self.final_truth_error_px
        data["final_offset_px"] = {
            "truth": self.final_truth_offset_px,
            "detector": self.final_detector_offset_px,
        }
        data["failures"] = list(self.failures)
        return data


def flight_outcome(results: list[InstructionResult], expected: list[Outcome]) -> Outcome:
    """A flight's outcome: the first instruction's that missed its expected outcome, else the last one's
    (ABORTED for a flight that flew none)."""
    for result, wanted in zip(results, expected, strict=True):
        if result.outcome is not wanted:
            return result.outcome
    return results[-1].outcome if results else Outcome.ABORTED
