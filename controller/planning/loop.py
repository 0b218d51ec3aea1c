"""The centring loop: Algorithm 1 of the paper, flown on the Vehicle, Camera, Detector and Planner interfaces.

Each step: read the newest frame → detect the target → the stop test on the
detection → centred? stop : the planner picks one of the 9 actions → execute it
as one discrete move (`flight.moves.execute_move`: a body velocity for a
duration, then hold until settled) → repeat, up to `max_steps` steps and
`timeout_s` on the vehicle's clock. Nothing here knows which backend it drives.

Stopping margin: the loop stops when the DETECTOR puts the target within
ε − `stop_margin_px` of the image centre on both axes, not within ε itself. The
detector is a measurement (its centre error is ~1–2 px), so stopping at exactly ε
per detector ends about half the boundary cases 10–12 px off per truth; the margin
buys "centred within ε per truth" for the cost of, rarely, one more small move.
Default: 2 px at 224 px width, scaled with the width (`default_stop_margin_px`).

Boundary refinement: near the boundary a planner may choose "no move" on an axis
(or on both) while the detector still sees the target outside the stop threshold
on it, e.g. the oracle judging by truth, or a learned planner whose own sense of ε
is a pixel or two wider. Where the detector's offset on such an axis lies in the
boundary band (stop threshold, ε + 2 × `stop_margin_px`], the loop flies the minimum
move (`min_move_m`) towards the detector's offset on that axis (beside the
planner's move on the other axis, if any), at most `max_refinements` steps per run.
A "no move" at all is refined only when no axis lies beyond the band. Each such
step is recorded (event "refinement") and counted in the report and the benchmark,
so the planner's own contribution stays visible. A "no move" otherwise, or after the
refinement budget, is a stall.

Second choice: "no move" far from centre (beyond the boundary band on some axis) means
the planner judged the view already at its goal while the detector, which decides when
to stop, says it is not; with several targets in view that is the planner taking another
target for the named one. Where the planner scored every action (`Plan.distances`: the
latent planner does), the loop flies the planner's best-ranked move instead, at most
`max_second_choices` times per run (event "second_choice", counted in the report and the
benchmark like refinements, so the planner's own choices stay visible). The direction is
still the planner's; the loop only declines "stay" when its own ε test says the target
is not centred. A "no move" after that budget, or from a planner without a ranking, is a
genuine stall: after `max_stalls` in a row the loop stops with `planner_stalled` instead
of burning the step budget.

Move lengths: the planner chooses the direction, the move schedule the length,
per axis (right/left, up/down). Fixed scheme (`scale_moves=False`, the paper's):
each axis starts at `move_m`; a reversal of direction on an axis (right after
left) multiplies its length by `shrink`, down to `min_move_m`: a fixed step longer
than the ε window would oscillate, halving on every reversal brackets the centre
like a bisection. Scaled scheme (default): the length on an axis is what the
detector's pixel offset on it means in metres at an assumed distance, through the
pinhole camera (`offset_px · assumed_distance_m / f_px`, f_px = (W/2)/tan(hfov/2)),
times `move_gain` < 1 so a closer-than-assumed target is not overshot much; clamped
to [`min_move_m`, the axis's cap], the cap starting at `max_move_m` and shrinking
on reversals as above. A far target is thus reached in one or two moves instead of
one 0.3 m move after another. Where the planner's direction disagrees with the
detector's sign on an axis, that axis flies the minimum move (the planner is
obeyed, but not trusted with a long move the detector contradicts). A move on both
axes takes the longer axis's time at `speed_m_s`; the shorter axis flies slower so
that both arrive together.

Target lost (the detector sees nothing): hold, and re-read up to `lost_rereads`
frames (a single missed detection is common). If it is still lost and a move
brought us here, undo that move once (bounded by `lost_recoveries` and by the
step budget, which it counts against; its axes' lengths shrink, since it overshot
out of view). Otherwise stop with the outcome
`target_lost`, holding. The loop never moves without a detection, except to
undo its own last move.

The named target: the detector reports every target it sees (`detect_all`; a detector
with only `detect` gives its one detection); the loop keeps the strongest one that the
instruction names (`CentringConfig.target`, else `parse_instruction(instruction)`;
`controller.planning.grounding`; named by its colour with several read so, the one that colour fits
best) and tests ε on it alone. Until the named target has
been found once in a run, no detection of it is "not found", not "lost": the loop holds
and re-reads up to `not_found_rereads` frames, never moving, then stops with
`target_not_found` and a message naming what was asked for and what was seen.

Found takes the detector and, where it says, the planner: a detection of the named kind and
colour is the target found only if the planner, asked on that frame whether that kind is in view
(`grounding.presence_query`: the kind alone; its presence head tells kinds apart but not twins'
colours, which the detector reads), does not say no (`Plan.in_view`: the latent planner's p(in
view) against its checkpoint's calibrated `presence_threshold`). A planner that gives no verdict
(`judges_presence` False or absent), or `confirm_with_planner` False, leaves it to the detector.
A frame where the detector sees a match but the planner says "not in view" is a not-found read
(event "not_in_view", p(in view) recorded): the loop holds, never moving towards that detection. The
verdict is asked for until the target is found, not after: once found, the target the loop
follows is the one both agreed on, and a presence read at every later step would add a chance of
a false "not in view" to every step of every centring.

A target asked for by its colour is found only when `colour_reads` reads in a row show a detection of
it near one place (`COLOUR_READ_PLACE`): a trim colour read on a small box, or on one the image's edge
cuts, can flip between frames of an unmoved camera (a red valve at the bottom edge read grey once and
red on the next reads, and the loop flew towards the "grey valve" it was asked for, which was not
there). The reads before that are not-found reads (event "colour_check", the detection kept in their
records), and count against `not_found_rereads`.
A kind asked for without a colour, with several of it in view when it is found: the loop takes the
strongest (`select_target`), and its message names every one of them and the one taken, so the operator
can name a colour instead.

Twins: two targets of one kind differ only in a thin trim band, which the detector reads and the
planner reads poorly. The planner is shown the frame with the other detections of the chosen
detection's kind painted over (`paint_over_twins`, on by default; `perception.masking`), so it
plans towards the one the loop tests ε on; the frame recorded is the camera's.

Every step is recorded (`StepRecord`: frame, detection, action, the planner's 9
distances, pose, timing) and handed to `on_step` as it happens, so a caller can
persist it before the next step; an exception leaves `loop.steps` holding every
step taken so far. Simulator truth, when the caller has it, is sampled per step
through `truth_probe` for the record only: it never steers the loop.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from controller.planning.actions import ALL_ACTIONS, Action, XMove, ZMove
from controller.planning.grounding import (
    TargetQuery,
    describe_seen,
    parse_instruction,
    planner_instruction,
    presence_query,
    select_target,
)
from controller.planning.loop_records import (
    CentringConfig,
    CentringResult,
    MoveSchedule,
    Outcome,
    StepEvent,
    StepRecord,
    StepTiming,
    TruthProbe,
)
from controller.planning.planners import Observation, Plan, Planner
from drone_inspect_core.centring import default_stop_margin_px, is_centred, offset_px
from flight.moves import MoveResult, fly_offset
from flight.vehicle import Deadline, Vehicle
from perception.camera import Camera
from perception.detector import Detector, detect_all
from perception.errors import CameraFrozenError
from perception.fresh_frame import read_fresh
from perception.masking import paint_over_twins
from perception.types import Detection, Frame

log = logging.getLogger(__name__)

COLOUR_READ_PLACE = 0.1
"""Two reads' detections of a target asked for by its colour are of one place when their centres lie
within this fraction of the image's width (the camera holds still between them)."""


# ------------------------------------------------------------------ the choices near and away from ε
# Pure functions of the detector's offset, the stop threshold and the planner's choice; the loop keeps
# the per-run budgets. The boundary band is (stop threshold, ε + 2 × stopping margin].


def sign(value: float) -> int:
    return (value > 0) - (value < 0)


def band_px(epsilon_px: float, stop_threshold_px: float) -> float:
    """The boundary band's outer edge: ε plus twice the stopping margin (ε − stop threshold)."""
    return epsilon_px + 2.0 * (epsilon_px - stop_threshold_px)


def refinement_signs(
    epsilon_px: float,
    stop_threshold_px: float,
    offset_px: tuple[float, float] | None,
    action: Action,
) -> tuple[int, int] | None:
    """(right, up) signs of the boundary refinement for `action`, or None where none applies.

    An axis is refined where the planner chose no move on it while the detector's offset on
    it lies in the boundary band; a "no move" at all is refined only if no axis lies beyond
    the band (else the planner is wrong, not the boundary).
    """
    if offset_px is None:
        return None
    edge = band_px(epsilon_px, stop_threshold_px)
    if action.is_none and max(abs(o) for o in offset_px) > edge:
        return None
    du, dv = offset_px
    towards = (sign(du), -sign(dv))  # target right → fly right; target below → fly down
    signs = tuple(
        want if chosen == 0 and stop_threshold_px < abs(off) <= edge else 0
        for off, chosen, want in zip((du, dv), action.direction(), towards, strict=True)
    )
    return signs if any(signs) else None  # type: ignore[return-value]


def second_choice(
    epsilon_px: float,
    stop_threshold_px: float,
    offset_px: tuple[float, float] | None,
    distances: Sequence[float] | None,
) -> Action | None:
    """The planner's best-ranked move after it chose "no move" with the target beyond the boundary
    band on some axis; None near the boundary (the refinement's business, or a fair "stay"), or
    where the planner did not rank every action."""
    if distances is None or offset_px is None:
        return None
    if max(abs(o) for o in offset_px) <= band_px(epsilon_px, stop_threshold_px):
        return None
    moves = [a for a in ALL_ACTIONS if not a.is_none]
    return min(moves, key=lambda a: distances[a.index])


@dataclass
class _RunState:
    """The loop's counters within one `run()`."""

    schedule: MoveSchedule
    start_s: float
    decisions: int = 0  # planner decisions plus recovery moves: what `max_steps` bounds
    stalls: int = 0
    refinements: int = 0
    second_choices: int = 0
    rereads: int = 0
    seen_target: bool = False  # the named target was found (detected, the planner not against) in this run
    colour_sightings: list[Detection] = field(default_factory=list)  # consecutive reads of an asked colour
    found_among: tuple[Detection, ...] = ()  # no colour asked: the kind's detections when found, taken first
    recoveries: int = 0
    last_move: tuple[Action, tuple[float, float]] | None = None
    before_move: np.ndarray | None = None  # the picture the last move was planned on


@dataclass
class CentringLoop:
    """Runs Algorithm 1 once per `run()`; `steps` keeps every step, even if `run()` raises."""

    vehicle: Vehicle
    camera: Camera
    detector: Detector
    planner: Planner
    config: CentringConfig
    truth_probe: TruthProbe | None = None
    on_step: Callable[[StepRecord], None] | None = None
    steps: list[StepRecord] = field(default_factory=list)

    def run(self) -> CentringResult:
        cfg = self.config
        first_length_m = cfg.max_move_m if cfg.scale_moves else cfg.move_m
        state = _RunState(MoveSchedule(first_length_m, cfg.min_move_m, cfg.shrink), self.vehicle.time_s())
        while True:
            t0 = time.perf_counter()
            record = self._observe_fresh(len(self.steps), state)
            outcome: Outcome | None = None
            unconfirmed = record.detection is not None and not state.seen_target
            if unconfirmed and not self._colour_read_enough(record, state):
                unconfirmed, record.event = False, StepEvent.COLOUR_CHECK  # a not-found read
            plan = self._confirm(record, state) if unconfirmed else None
            if unconfirmed and state.seen_target and self.target.attribute is None:
                chosen = record.detection
                others = (d for d in record.detections if d.kind == chosen.kind and d is not chosen)
                state.found_among = (chosen, *others)  # the one taken first
            if not state.seen_target:
                outcome = self._on_not_found(record, state)
            elif record.detection is None:
                outcome = self._on_lost(record, state)
            elif record.centred:
                record.event, outcome = StepEvent.CENTRED, Outcome.CENTRED
            elif state.decisions >= cfg.max_steps:
                record.event, outcome = StepEvent.MAX_STEPS, Outcome.MAX_STEPS
            elif self.vehicle.time_s() - state.start_s > cfg.timeout_s:
                record.event, outcome = StepEvent.TIMEOUT, Outcome.TIMEOUT
            else:
                outcome = self._decide_and_move(record, state, plan)
            read_s, detect_s, plan_s = record.timing.read_s, record.timing.detect_s, record.timing.plan_s
            move_s = record.move.wall_time_s if record.move is not None else 0.0
            record.timing = StepTiming(read_s, detect_s, plan_s, move_s, time.perf_counter() - t0)
            self._keep(record)
            if outcome is not None:
                self.vehicle.hold()
                message = self._message(outcome, state.decisions, record) + self._choice_note(state)
                log.info("centring loop: %s", message)
                return CentringResult(outcome, self.steps, message)

    def _plan(self, record: StepRecord, query: TargetQuery | None = None) -> Plan:
        """Ask the planner about `record`'s frame for `query` (default: the named target), timed."""
        t_plan = time.perf_counter()
        observation = Observation(
            self._planner_picture(record),
            record.detection,
            self._planner_words(record.detection, query),
            self.config.epsilon_px,
            record.stop_threshold_px,
            record.detections,
        )
        plan = self.planner.plan(observation)
        record.timing = replace(record.timing, plan_s=record.timing.plan_s + time.perf_counter() - t_plan)
        return plan

    def _planner_picture(self, record: StepRecord) -> np.ndarray:
        """The frame the planner sees: with the other detections of the chosen one's kind painted over
        (`paint_over_twins`; see the module docstring), else the frame itself."""
        chosen = record.detection
        if not self.config.paint_over_twins or chosen is None:
            return record.frame.image
        return paint_over_twins(record.frame.image, chosen, record.detections)

    def _colour_read_enough(self, record: StepRecord, state: _RunState) -> bool:
        """Before the target is found, its detection on this read: whether `colour_reads` reads in a row
        (this one the last) showed it near one place. Always True when no colour was asked for."""
        if self.target.attribute is None:
            return True
        detection, seen = record.detection, state.colour_sightings
        assert detection is not None
        reach = COLOUR_READ_PLACE * record.frame.width
        if seen and math.dist(seen[-1].centre_px, detection.centre_px) > reach:
            seen.clear()
        seen.append(detection)
        return len(seen) >= self.config.colour_reads

    def _confirm(self, record: StepRecord, state: _RunState) -> Plan | None:
        """The named target detected before it was found in this run: found unless the planner says its
        kind is not in view (`grounding.presence_query`; the read is then a not-found one, event
        "not_in_view"). Returns the plan where it was asked in the named target's own words."""
        if not (self.config.confirm_with_planner and getattr(self.planner, "judges_presence", False)):
            state.seen_target = True
            return None
        asked = presence_query(self.target, record.detection)
        plan = self._plan(record, asked)
        record.presence = plan.presence
        if plan.in_view is False:
            record.event = StepEvent.NOT_IN_VIEW
        else:
            state.seen_target = True
        return (
            plan
            if self._planner_words(record.detection, asked) == self._planner_words(record.detection)
            else None
        )

    def _decide_and_move(
        self, record: StepRecord, state: _RunState, plan: Plan | None = None
    ) -> Outcome | None:
        """The target is seen and not centred: ask the planner (unless it was asked on this frame), fly
        its action."""
        cfg = self.config
        state.rereads = 0
        plan = plan if plan is not None else self._plan(record)
        state.decisions += 1
        record.action, record.distances = plan.action, plan.distances
        refine = self._refinement(record, state, plan.action)
        action = plan.action
        second = self._second_choice(record, state, plan) if action.is_none and refine is None else None
        if second is not None:
            action = second
            state.second_choices += 1
            record.event = StepEvent.SECOND_CHOICE
        if action.is_none and refine is None:
            state.stalls += 1
            record.event = StepEvent.STALL
            if state.stalls >= cfg.max_stalls:
                return Outcome.PLANNER_STALLED
            self.vehicle.sleep(cfg.settle_s)
            return None
        move = [0.0, 0.0]
        if not action.is_none:
            move = list(state.schedule.lengths_for(action, self._wanted_m(record, action)))
        if refine is not None:
            state.refinements += 1
            record.event = StepEvent.REFINEMENT
            for axis, towards in enumerate(refine):
                if towards:
                    move[axis] = towards * cfg.min_move_m
        state.stalls = 0
        record.move_m = (move[0], move[1])
        record.move = self._fly(*record.move_m)
        state.before_move = record.frame.image
        moved = Action(XMove(sign(move[0]) + 1), ZMove(1 - sign(move[1])))
        state.last_move = (moved, record.move_m)
        return None

    def _wanted_m(self, record: StepRecord, action: Action) -> tuple[float, float] | None:
        """Scaled scheme: per axis, the length the detector's offset asks for (see the module docstring)."""
        cfg = self.config
        if not cfg.scale_moves or record.offset_px is None:
            return None
        du, dv = record.offset_px
        focal_px = record.frame.width / 2.0 / math.tan(math.radians(cfg.hfov_deg) / 2.0)
        metres_per_px = cfg.move_gain * cfg.assumed_distance_m / focal_px
        towards = (sign(du), -sign(dv))  # target right → fly right; target below (dv > 0) → fly down
        return tuple(  # type: ignore[return-value]
            abs(off) * metres_per_px if sign == want else 0.0  # disagreeing: clamped up to the minimum
            for off, sign, want in zip((du, dv), action.direction(), towards, strict=True)
        )

    def _second_choice(self, record: StepRecord, state: _RunState, plan: Plan) -> Action | None:
        """`second_choice`, while the run's second-choice budget lasts."""
        if state.second_choices >= self.config.max_second_choices or record.stop_threshold_px is None:
            return None
        return second_choice(
            self.config.epsilon_px, record.stop_threshold_px, record.offset_px, plan.distances
        )

    def _refinement(self, record: StepRecord, state: _RunState, action: Action) -> tuple[int, int] | None:
        """`refinement_signs`, while the run's refinement budget lasts."""
        if state.refinements >= self.config.max_refinements or record.stop_threshold_px is None:
            return None
        return refinement_signs(self.config.epsilon_px, record.stop_threshold_px, record.offset_px, action)

    def _on_not_found(self, record: StepRecord, state: _RunState) -> Outcome | None:
        """The named target not found yet in this run (not detected, or detected where the planner says
        it is not in view): hold and re-read (bounded), never move."""
        self.vehicle.hold()
        if record.detection is None:
            state.colour_sightings.clear()
        if record.event not in (StepEvent.NOT_IN_VIEW, StepEvent.COLOUR_CHECK):
            record.event = StepEvent.NOT_FOUND
        if state.rereads < self.config.not_found_rereads:
            state.rereads += 1
            self.vehicle.sleep(self.config.settle_s)
            return None
        return Outcome.TARGET_NOT_FOUND

    def _on_lost(self, record: StepRecord, state: _RunState) -> Outcome | None:
        """No detection: hold; re-read, then undo the last move once, then give up (bounded)."""
        cfg = self.config
        self.vehicle.hold()
        record.event = StepEvent.LOST
        if state.rereads < cfg.lost_rereads:
            state.rereads += 1
            self.vehicle.sleep(cfg.settle_s)
            return None
        within_budget = state.decisions < cfg.max_steps  # a recovery move is a step of the budget too
        if state.last_move is not None and state.recoveries < cfg.lost_recoveries and within_budget:
            action, (right_m, up_m) = state.last_move
            log.warning("target lost after moving %s: undoing that move", action.name)
            for axis, length in enumerate((right_m, up_m)):
                if length:
                    state.schedule.shrink_axis(axis)
            record.event, record.move_m = StepEvent.RECOVERY, (-right_m, -up_m)
            record.move = self._fly(-right_m, -up_m)
            state.recoveries += 1
            state.decisions += 1
            state.last_move, state.rereads = None, 0
            return None
        return Outcome.TARGET_LOST

    def _observe_fresh(self, index: int, state: _RunState) -> StepRecord:
        """`_observe`, refusing a frozen camera: after a move the picture must change.

        A stuck encoder keeps sending the last picture with new frame numbers; planning on it
        would repeat the same move again and again. A bit-identical picture after a move is
        re-read for up to `frame_timeout_s` (a short freeze passes), then `CameraFrozenError`.
        """
        record = self._observe(index)
        before, state.before_move = state.before_move, None
        if before is None or not np.array_equal(record.frame.image, before):
            return record
        cfg = self.config
        deadline = Deadline(self.vehicle, cfg.frame_timeout_s)  # frames come at wall-clock rates
        log.warning("camera picture unchanged after a move: waiting for a fresh one")
        while not deadline.expired():
            self.vehicle.sleep(cfg.settle_s)
            record = self._observe(index)
            if not np.array_equal(record.frame.image, before):
                return record
        raise CameraFrozenError(
            getattr(self.camera, "name", "camera"),
            f"the picture has not changed for {cfg.frame_timeout_s:g} s after a move: the stream is frozen",
        )

    def _observe(self, index: int) -> StepRecord:
        t0 = time.perf_counter()
        frame = self._read_fresh()
        telemetry = self.vehicle.telemetry()
        vehicle_time_s = self.vehicle.time_s()
        truth = self.truth_probe() if self.truth_probe is not None else None
        t1 = time.perf_counter()
        detections = detect_all(self.detector, frame.image)
        detection = select_target(detections, self.target)
        t2 = time.perf_counter()
        offset = offset_px(detection, frame.width, frame.height) if detection is not None else None
        threshold = self._stop_threshold_px(frame.width)
        centred = is_centred(detection, threshold, frame.width, frame.height)
        timing = StepTiming(t1 - t0, t2 - t1, 0.0, 0.0, 0.0)
        return StepRecord(
            index, frame, detection, offset, truth, centred, telemetry, vehicle_time_s, timing=timing,
            stop_threshold_px=threshold, detections=detections,
        )  # fmt: skip

    @property
    def target(self) -> TargetQuery:
        """What the loop centres: the configured query, else the instruction's reading."""
        return self.config.target or parse_instruction(self.config.instruction, self.config.vocabulary)

    def _planner_words(self, detection: Detection | None, query: TargetQuery | None = None) -> str:
        """What the planner hears: the target the loop tests ε on (or `query`), in the words the planner
        trained on (`grounding.planner_instruction`); an unnamed kind is the kind of the detection it
        centres."""
        query = query or self.target
        if query.kind is None and detection is not None and detection.kind is not None:
            query = TargetQuery(detection.kind, query.attribute)
        return planner_instruction(query, self.config.vocabulary)

    def stop_threshold_px(self, width: int) -> float:
        """ε minus the stopping margin for images `width` px wide; ValueError when that leaves nothing."""
        return self._stop_threshold_px(width)

    def _stop_threshold_px(self, width: int) -> float:
        cfg = self.config
        margin = cfg.stop_margin_px if cfg.stop_margin_px is not None else default_stop_margin_px(width)
        if not 0 <= margin < cfg.epsilon_px:
            raise ValueError(
                f"ε = {cfg.epsilon_px:g} px leaves nothing inside the stopping margin of {margin:g} px "
                f"(for {width} px wide images): give a larger epsilon_px or a smaller stop_margin_px"
            )
        return cfg.epsilon_px - margin

    def _read_fresh(self) -> Frame:
        """The camera's next frame; off real time (`fresh_frame_s` > 0) the first that shows the scene as
        it was at this call (`perception.fresh_frame`: by the frame's scene stamp, else `fresh_frame_s`
        of arrival margin; bounded)."""
        cfg = self.config
        if cfg.fresh_frame_s <= 0:
            return self.camera.read(cfg.frame_timeout_s)
        return read_fresh(self.camera, time.monotonic(), cfg.fresh_frame_s, cfg.frame_timeout_s)

    def _fly(self, right_m: float, up_m: float) -> MoveResult:
        cfg = self.config
        return fly_offset(
            self.vehicle, right_m, up_m, cfg.speed_m_s, cfg.settle_speed_m_s, cfg.settle_timeout_s
        )

    def _keep(self, record: StepRecord) -> None:
        self.steps.append(record)
        if self.on_step is not None:
            self.on_step(record)

    def _choice_note(self, state: _RunState) -> str:
        """With no colour asked and several targets of the kind in view when it was found: which one the
        loop took, and how to ask for another ("" otherwise)."""
        seen = state.found_among
        if len(seen) < 2:
            return ""
        return (
            f"; {len(seen)} of that kind were in view ({describe_seen(seen)}): it took the strongest, "
            f"{describe_seen(seen[:1])}; name a colour to choose"
        )

    def _message(self, outcome: Outcome, decisions: int, last: StepRecord) -> str:
        cfg = self.config
        if outcome is Outcome.TARGET_NOT_FOUND and last.event is StepEvent.NOT_IN_VIEW:
            asked = presence_query(self.target, last.detection).describe()
            return (
                f"no {self.target.describe()} in view: the detector saw "
                f"{describe_seen((last.detection,) if last.detection else ())}, but the planner says no "
                f"{asked} is in view (p(in view) {last.presence or 0.0:.3f}, below its threshold); saw: "
                f"{describe_seen(last.detections)}"
            )
        if outcome is Outcome.TARGET_NOT_FOUND:
            return f"no {self.target.describe()} in view; saw: {describe_seen(last.detections)}"
        return {
            Outcome.CENTRED: f"centred within {cfg.epsilon_px:g} px (detector) after {decisions} steps",
            Outcome.MAX_STEPS: f"not centred after the step budget of {cfg.max_steps}",
            Outcome.TIMEOUT: f"not centred within {cfg.timeout_s:g} s",
            Outcome.TARGET_LOST: "target lost from view; holding position",
            Outcome.PLANNER_STALLED: f"planner chose 'no move' {cfg.max_stalls} times while not centred",
            Outcome.ABORTED: "aborted",
        }[outcome]
