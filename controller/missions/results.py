"""Missions: finding mission files, judging a flown mission against its expectations, the result row.

The file format is `controller.missions.schema`; flying one is
`controller.missions.runner`. A mission passes when the loop's outcome is the
expected one and every expectation holds; "centred" is judged by simulator
truth where the mission has it (the detector could be wrong), otherwise by the
detector's final offset.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

from controller.missions.schema import Mission
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
) -> int | None:
    """A wrong-target centring: the loop ended `centred`, the named target is not within ε per truth,
    and another target is. Returns that target's index in the scene (the named one is 0), else None.

    `targets_truth`: every target's true offset at the end, the named one first (None: no such truth,
    e.g. a kit other than the in-process sim); its first entry is not used (`final_truth_offset_px`
    judges the named one, as for success)."""
    if outcome is not Outcome.CENTRED or not targets_truth:
        return None
    if final_truth_offset_px is not None and _error_px(final_truth_offset_px) <= epsilon_px:
        return None
    for index, offset in enumerate(targets_truth[1:], start=1):
        if offset is not None and _error_px(offset) <= epsilon_px:
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
) -> list[str]:
    """Every expectation of `mission` that the flight broke, in words; empty when it passed.
    `wrong_target_index`: see `wrong_target` (a wrong-target centring never passes)."""
    expect = mission.expect
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
