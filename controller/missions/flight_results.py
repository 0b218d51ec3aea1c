"""What a flight session's loop runs come to: each instruction judged, and the flight's result and report.

An instruction is judged as a one-instruction mission always was (`results.judge`: its expected outcome,
centred within ε per truth where there is truth, its step budget, a wrong-target centring never passes),
against its own expectations (`MissionInstruction.expect`, else the mission's), on the truth of the
target it names (`controller.missions.truth`); where the last step's truth did not come (a simulator's
`/truth.json` that timed out) but the detector saw the target, on the truth read when the loop ended.
The flight passes when every instruction the mission planned was flown and passed and nothing failed.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any

from controller.missions.phases import flight_phases
from controller.missions.results import (
    InstructionResult,
    MissionResult,
    count_steps,
    flight_outcome,
    judge,
    wrong_target,
)
from controller.missions.schema import MissionInstruction
from controller.missions.truth import named_indices, named_offset
from controller.planning.grounding import TargetQuery
from controller.planning.loop_records import (
    Outcome,
    StepRecord,
    count_not_in_view,
    count_refinements,
    count_second_choices,
)

if TYPE_CHECKING:
    from controller.missions.session import FlightSession


def judge_instruction(
    session: FlightSession,
    index: int,
    entry: MissionInstruction,
    query: TargetQuery,
    steps: list[StepRecord],
    outcome: Outcome,
    message: str,
    error: str | None,
    wall_s: float,
    vehicle_s: float,
    returned_to_start: bool = False,
) -> InstructionResult:
    """One instruction's result: its loop's `steps` and `outcome`, judged (see the module docstring)."""
    kit, epsilon_px = session.kit, session.epsilon_px
    final_truth = steps[-1].truth_offset_px if steps else None
    final_detector = steps[-1].offset_px if steps else None
    targets = kit.targets_truth() if kit.targets_truth is not None and error is None else None
    offsets = None if targets is None else [t.offset_px for t in targets]
    if final_truth is None and targets is not None and steps and steps[-1].detection is not None:
        # The last step's truth did not come (a simulator's /truth.json timed out under load) while the
        # detector saw the target: judge by the truth read when the loop ended, the vehicle holding.
        final_truth = named_offset(targets, query)
    named = (0,) if targets is None else named_indices(targets, query)
    wrong = wrong_target(outcome, epsilon_px, final_truth, offsets, named)
    n_steps = count_steps(steps)
    has_truth = kit.truth_probe is not None
    failures = judge(
        session.mission, outcome, n_steps, epsilon_px, final_truth, final_detector, has_truth, wrong,
        expect=entry.expect,
    )  # fmt: skip
    if error is not None:
        failures.insert(0, f"error: {error}")
    return InstructionResult(
        index=index,
        instruction=entry.instruction,
        target={"kind": query.kind, "attribute": query.attribute},
        outcome=outcome,
        message=message,
        passed=not failures,
        failures=tuple(failures),
        steps=n_steps,
        moves=sum(1 for s in steps if s.move is not None),
        refinement_moves=count_refinements(steps),
        second_choice_moves=count_second_choices(steps),
        final_truth_offset_px=final_truth,
        final_detector_offset_px=final_detector,
        wrong_target_index=wrong,
        targets_truth_final_px=offsets,
        vehicle_s=round(vehicle_s, 3),
        wall_s=round(wall_s, 3),
        error=error,
        returned_to_start=returned_to_start,
        not_in_view_reads=count_not_in_view(steps),
        records=tuple(steps),
    )


def flight_failures(session: FlightSession, results: list[InstructionResult]) -> list[str]:
    """Everything that failed in the flight, in words: its errors, each instruction's failures (named by
    its number where there are several), the planned instructions not flown."""
    failures = [f"error: {error}" for error in session.errors]
    several = len(session.planned) > 1 or len(results) > 1
    for result in results:
        own = [f for f in result.failures if not f.startswith("error: ")]  # the flight's errors are above
        failures += [
            f"instruction {result.index} ({result.instruction!r}): {f}" if several else f for f in own
        ]
    flown = len(results)
    for number, (entry, _) in enumerate(session.planned[flown:], start=flown + 1):
        if session.flying_the_plan:
            failures.append(f"instruction {number} ({entry.instruction!r}) was not flown")
    if not results and not failures:
        failures.append("no instruction was flown")
    return failures


def finish_flight(session: FlightSession) -> MissionResult:
    """Finish the Rerun recording and the report of a closed session; the flight's `MissionResult`."""
    kit, writer, results = session.kit, session.writer, session.results
    failures = flight_failures(session, results)
    expected = [(r_entry.expect or session.mission.expect).outcome for r_entry in _entries(session, results)]
    outcome = flight_outcome(results, expected) if results else Outcome.ABORTED
    last = results[-1] if results else None
    error = session.errors[0] if session.errors else None
    if error is not None:
        message = error
    elif len(results) == 1:
        message = results[0].message
    else:
        centred = sum(r.outcome is Outcome.CENTRED for r in results)
        message = f"{centred} of {len(results)} instructions centred"
    if session.recorder is not None:
        try:
            session.recorder.finish(outcome.value, message)
        except Exception as exc:
            writer.recording_errors.append(f"the Rerun recording: {exc}")
    start, end = session.vehicle_start_s, session.vehicle_end_s
    vehicle_s = max(0.0, end - start) if start is not None and end is not None else 0.0
    wall_s = session.wall_s
    phases = flight_phases(session.milestones_wall_s, [s.timing for r in results for s in r.records])
    summary: dict[str, Any] = {
        "outcome": outcome.value,
        "message": message,
        "passed": not failures,
        "failures": failures,
        "steps": sum(r.steps for r in results),
        "moves": sum(r.moves for r in results),
        "refinement_moves": sum(r.refinement_moves for r in results),
        "second_choice_moves": sum(r.second_choice_moves for r in results),
        "not_in_view_reads": sum(r.not_in_view_reads for r in results),
        "final_offset_px": {
            "truth": None if last is None else last.final_truth_offset_px,
            "detector": None if last is None else last.final_detector_offset_px,
        },
        "wrong_target": any(r.wrong_target for r in results),
        "wall_s": round(wall_s, 3),
        "vehicle_s": round(vehicle_s, 3),
        "vehicle_clock_s": {name: round(value, 3) for name, value in session.vehicle_clock_s.items()},
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
        name=session.mission.name,
        planner=kit.planner.name,
        outcome=outcome,
        passed=not failures,
        failures=tuple(failures),
        steps=summary["steps"],
        moves=summary["moves"],
        epsilon_px=session.epsilon_px,
        final_truth_offset_px=summary["final_offset_px"]["truth"],
        final_detector_offset_px=summary["final_offset_px"]["detector"],
        wall_s=wall_s,
        vehicle_s=vehicle_s,
        overhead_ms_mean=final["timing"]["overhead_ms_mean"],
        report_dir=str(writer.out_dir),
        error=error,
        tags=session.mission.tags,
        info=kit.info,
        refinement_moves=summary["refinement_moves"],
        second_choice_moves=summary["second_choice_moves"],
        not_in_view_reads=summary["not_in_view_reads"],
        vehicle_clock_s=summary["vehicle_clock_s"],
        files=final["files"],
        truth_extremes=summary["truth_extremes"],
        wrong_target=summary["wrong_target"],
        recording_errors=tuple(final["recording_errors"]),
        report_written=final["report_written"],
        instructions=tuple(r.summary() for r in results),
        phases_s=phases,
    )


def _entries(session: FlightSession, results: list[InstructionResult]) -> list[MissionInstruction]:
    """The entries the results were flown for (their expectations)."""
    return [session.flown_entries[r.index - 1] for r in results]
