"""Planners: what picks one of the 9 actions for the centring loop, behind one interface.

- `LatentPlannerAdapter` (default): the paper's latent dynamics planner (Algorithm 1's
  inner loop): scores all 9 actions by the predicted distance to the goal prototype.
- `ClassicPlanner`: the alternative the paper names: the detector's target centre →
  a direction per axis, with a deadband; no learning. It picks its target among the
  detections with the keyword parser (`controller.planning.grounding`).
- `RandomPlanner`: a seeded baseline; one of the 8 moving actions uniformly.
- `OraclePlanner`: the labelling rule applied to simulator truth. For judging only
  (the "steps over the oracle's" ratio); a real vehicle has no truth.

The loop calls a planner only while the target is detected and not centred.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, Protocol

import numpy as np

from controller.planning.actions import ALL_ACTIONS, Action, label_from_offset
from controller.planning.grounding import parse_instruction, select_target
from perception.types import Detection

log = logging.getLogger(__name__)

DEFAULT_CHECKPOINT = Path(__file__).resolve().parent / "assets" / "latent_cpu"
"""The shipped CPU checkpoint of the latent planner."""

TruthOffset = Callable[[], "tuple[float, float] | None"]
"""Simulator truth: the target centre's offset (du, dv) from the image centre in pixels, None out of view."""


@dataclass(frozen=True)
class Observation:
    """What a planner sees at one step."""

    image: np.ndarray  # RGB uint8 (H, W, 3)
    detection: Detection | None
    """The named target's detection, as the loop chose it (`CentringConfig.target`)."""
    instruction: str
    epsilon_px: float
    stop_threshold_px: float | None = None
    """Where the loop stops, per detector: ε − its stopping margin (None: ε)."""
    detections: tuple[Detection, ...] = ()
    """Everything the detector saw, strongest first (empty: only `detection` is known)."""

    @property
    def offset_px(self) -> tuple[float, float] | None:
        """The detected target centre minus the image centre (du, dv), None when nothing was detected."""
        return self.offset_of(self.detection)

    def offset_of(self, detection: Detection | None) -> tuple[float, float] | None:
        """`detection`'s centre minus the image centre (du, dv), None for None."""
        if detection is None:
            return None
        height, width = self.image.shape[:2]
        return detection.centre_px[0] - width / 2.0, detection.centre_px[1] - height / 2.0


@dataclass(frozen=True)
class Plan:
    """A planner's choice and, for a planner that scores actions, its 9 scores (lower is better); for
    one that says how sure it is that the asked-for target is in view, that too."""

    action: Action
    distances: tuple[float, ...] | None = None
    presence: float | None = None
    """p(the asked-for target in view), where the planner gives one (recorded; `in_view` is the verdict)."""
    in_view: bool | None = None
    """The planner's verdict on `presence` at its calibrated threshold: False, the asked-for target is
    not in view (the loop then moves towards no detection); None, the planner does not say."""

    def __post_init__(self) -> None:
        if self.distances is not None and len(self.distances) != len(ALL_ACTIONS):
            raise ValueError(
                f"a plan scores all {len(ALL_ACTIONS)} actions, got {len(self.distances)} distances"
            )


class Planner(Protocol):
    """Picks the next action; `name` identifies it in reports. A planner whose plans say whether the
    asked-for target is in view (`Plan.in_view`) also has `judges_presence = True`."""

    name: str

    def plan(self, observation: Observation) -> Plan: ...


class LatentPlannerAdapter:
    """The latent dynamics planner (`controller.planning.latent`) on the `Planner` interface.

    The model scores every action by the distance from the predicted next latent
    state to the goal prototype; the loop records all 9 distances. A checkpoint with a presence head
    and a calibrated threshold also says whether the asked-for target is in view (`Plan.in_view`).
    """

    name = "latent"

    def __init__(self, checkpoint_dir: str | Path | None = None, threads: int = 1) -> None:
        # Imported here: torch is paid for only when the latent planner is chosen.
        from controller.planning.latent.planner import LatentPlanner

        self.checkpoint_dir = Path(checkpoint_dir) if checkpoint_dir is not None else DEFAULT_CHECKPOINT
        # One torch thread: a single image per step gains nothing from more, and on a busy 2-core
        # machine two threads made a plan take ~900 ms instead of ~5 ms (measured).
        self._planner = LatentPlanner(self.checkpoint_dir, threads=threads)

    @property
    def judges_presence(self) -> bool:
        """Whether its plans say if the asked-for target is in view (`Plan.in_view`): a presence head and
        a calibrated threshold. The loop asks only a planner that does (`planning.loop`)."""
        return self.presence_threshold is not None

    @property
    def presence_threshold(self) -> float | None:
        """p(in view) below which its plans say the asked-for target is not in view; None: no verdict."""
        return self._planner.presence_threshold

    def plan(self, observation: Observation) -> Plan:
        actions, distances, presence = self._planner.plan_with_presence(
            [observation.image], observation.instruction
        )
        p = None if presence is None else float(presence[0])
        return Plan(actions[0], tuple(float(d) for d in distances[0]), p, self._planner.in_view(p))


class ClassicPlanner:
    """Detector bounding box → direction, per axis, with a deadband (no learning).

    Its target is the loop's (`observation.detection`, the detection the loop tests ε on);
    without one, its own reading of the instruction (`parse_instruction`, then
    `select_target` among `observation.detections`).
    Moves on an axis only when the detected centre lies more than `deadband_px`
    from the image centre on it; `deadband_px` None uses the loop's stop threshold
    (ε less the stopping margin), so the classic pipeline stops moving exactly where
    the loop's stop test says "centred".
    """

    name = "classic"

    def __init__(self, deadband_px: float | None = None) -> None:
        if deadband_px is not None and deadband_px < 0:
            raise ValueError(f"deadband_px must be >= 0, got {deadband_px}")
        self.deadband_px = deadband_px

    def plan(self, observation: Observation) -> Plan:
        target = observation.detection
        if target is None and observation.detections:
            target = select_target(observation.detections, parse_instruction(observation.instruction))
        offset = observation.offset_of(target)
        if offset is None:
            log.warning("classic planner: no detection of the instructed target: choosing no move")
            return Plan(ALL_ACTIONS[4])
        deadband = self.deadband_px
        if deadband is None:
            threshold = observation.stop_threshold_px
            deadband = observation.epsilon_px if threshold is None else threshold
        return Plan(label_from_offset(offset[0], offset[1], deadband))


class RandomPlanner:
    """Uniform over the 8 moving actions, from a seeded generator (reproducible)."""

    name = "random"

    def __init__(self, seed: int = 0) -> None:
        self._rng = np.random.default_rng(seed)
        self._moving = tuple(a for a in ALL_ACTIONS if not a.is_none)

    def plan(self, observation: Observation) -> Plan:
        return Plan(self._moving[int(self._rng.integers(len(self._moving)))])


class OraclePlanner:
    """The labelling rule on simulator truth (judging only): the correct action at every step."""

    name = "oracle"

    def __init__(self, truth_offset: TruthOffset) -> None:
        self._truth_offset = truth_offset

    def plan(self, observation: Observation) -> Plan:
        offset = self._truth_offset()
        if offset is None:
            log.warning("oracle: the target is out of view per truth: choosing no move")
            return Plan(ALL_ACTIONS[4])
        return Plan(label_from_offset(offset[0], offset[1], observation.epsilon_px))


@dataclass(frozen=True)
class PlannerOptions:
    """What building a planner may use: a checkpoint, a seed, simulator truth, a deadband."""

    checkpoint: str | Path | None = None
    seed: int = 0
    truth_offset: TruthOffset | None = None
    deadband_px: float | None = None


@dataclass(frozen=True)
class PlannerKind:
    """One planner in the registry: its name, what it is, whether it needs simulator truth, a builder."""

    name: str
    summary: str
    build: Callable[[PlannerOptions], Planner]
    needs_truth: bool = False


def _oracle(options: PlannerOptions) -> Planner:
    if options.truth_offset is None:
        raise ValueError("the oracle planner needs simulator truth, which this vehicle does not provide")
    return OraclePlanner(options.truth_offset)


PLANNERS: dict[str, PlannerKind] = {
    kind.name: kind
    for kind in (
        PlannerKind(
            "latent", "the paper's latent dynamics model", lambda o: LatentPlannerAdapter(o.checkpoint)
        ),
        PlannerKind(
            "classic", "the detector's offset with a deadband", lambda o: ClassicPlanner(o.deadband_px)
        ),
        PlannerKind("random", "a seeded random move (a baseline)", lambda o: RandomPlanner(o.seed)),
        PlannerKind("oracle", "the labelling rule on simulator truth (judging)", _oracle, needs_truth=True),
    )
}
"""The one registry of planners: mission files, the command line and benchmarks take their names from it."""
PLANNER_NAMES: tuple[str, ...] = tuple(PLANNERS)
PlannerName = Literal[PLANNER_NAMES]  # type: ignore[valid-type]
"""A planner's name, as a type (for validated config models)."""


def make_planner(
    name: str,
    *,
    checkpoint: str | Path | None = None,
    seed: int = 0,
    truth_offset: TruthOffset | None = None,
    deadband_px: float | None = None,
) -> Planner:
    """Build a planner by name (one of `PLANNER_NAMES`)."""
    kind = PLANNERS.get(name)
    if kind is None:
        raise ValueError(f"unknown planner {name!r}: choose one of {', '.join(PLANNER_NAMES)}")
    return kind.build(PlannerOptions(checkpoint, seed, truth_offset, deadband_px))
