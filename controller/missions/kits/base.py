"""`FlightKit`: the components one centring flight needs, however they were built; `OpenedVehicle`: the part
of it that every flight over MAVLink opens first (a vehicle and its camera).

`controller.missions.runner` builds a kit per mission backend (in-process sim,
sim-vehicle over MAVLink, a real vehicle); tests build one from fakes. The loop
and the report see only this, never the backend. A flown collection
(`controller.collection`) opens only the vehicle and its camera (`OpenedVehicle`), the same way.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from controller.missions.schema import Mission
from controller.missions.truth import TargetsTruth, TruthFollower
from controller.planning.grounding import TargetQuery
from controller.planning.loop_records import TruthProbe
from controller.planning.planners import Planner, make_planner
from flight.vehicle import Vehicle
from perception.camera import Camera
from perception.detector import Detector

if TYPE_CHECKING:  # kits.warm imports MAVSDK: a kit that keeps nothing warm never loads it
    from controller.missions.kits.warm import WarmSimulators

TLOG_NAME = "flight.tlog"


class TlogRecording(Protocol):
    """A .tlog being recorded (`flight.relay.MavlinkRelay`): where it is now, and why it stopped early."""

    @property
    def path(self) -> Path | None: ...

    @property
    def recording_error(self) -> str | None: ...


@dataclass
class OpenedVehicle:
    """A vehicle and its camera, open, with what a report says about them: the first half of every kit over
    MAVLink (sim-vehicle, PX4 SITL, a real vehicle), and all that a flown collection needs."""

    vehicle: Vehicle
    camera: Camera
    info: dict[str, Any]
    tlog: TlogRecording | None = None


@dataclass
class FlightKit:
    """Everything one flight needs, built from a mission (or from fakes in tests)."""

    vehicle: Vehicle
    camera: Camera
    detector: Detector
    planner: Planner
    instruction: str
    image_width_px: int
    """The camera's image width: ε's default scales with it (resolved once, by the runner)."""
    truth_probe: TruthProbe | None = None
    """Judging only: the true target offset in pixels (None without a simulator)."""
    place_at_start: Callable[[], None] | None = None
    """In-process sim only: put the hovering drone at the mission's start pose after takeoff."""
    takeoff_altitude_m: float | None = None
    """The takeoff altitude where the start pose needs one (sim-vehicle); None: the mission's."""
    info: dict[str, Any] = field(default_factory=dict)
    """What the report should say about the setup (scene seed, target kind, start offset, URLs)."""
    tlog: TlogRecording | None = None
    """The .tlog being recorded (the relay), if any: its path and why it stopped early, if it did."""
    truth_extremes: Callable[[], dict[str, Any] | None] | None = None
    """Judging only: the simulator's largest speeds and excursions from home over the flight."""
    epsilon_px: float | None = None
    """ε when the kit fixes it (tests); None: the mission's, else `default_epsilon_px(image_width_px)`."""
    target: TargetQuery | None = None
    """What `instruction` names, where the kit knows it from the scene (the named target's kind and
    colour); None: the instruction's own reading (a real vehicle; a kit built in a test)."""
    targets_truth: TargetsTruth | None = None
    """Judging only: every target's truth now (`controller.missions.truth.TrueTarget`: kind, colour,
    offset), the named one first; None where the kit cannot tell (a real vehicle). The simulators
    (in-process, sim-vehicle, the PX4 and ArduPilot bridges) can: wrong-target judging."""
    aim_truth: Callable[[TargetQuery | None], None] | None = None
    """Judging only: point `truth_probe` at the target an instruction names (`TruthFollower.follow`);
    None where the kit has no per-target truth (`truth_probe` is then the named target's)."""

    @classmethod
    def judged_by(cls, follower: TruthFollower, **fields: Any) -> FlightKit:
        """A kit whose truth follows each instruction's target: `truth_probe`, `targets_truth` and
        `aim_truth` from `follower`."""
        return cls(
            truth_probe=follower.offset_px,
            targets_truth=follower.targets,
            aim_truth=follower.follow,
            **fields,
        )


def named_target(mission: Mission, targets: list[tuple[str, str]]) -> tuple[str, TargetQuery]:
    """The instruction resolved from a simulated scene whose targets are `targets` ((kind, trim colour
    name), the named one first), for a mission that gives none, and the loop's target for it.

    The colour is included where the kind alone would not say which, and the loop's target is the
    named target's kind and that colour, from the scene itself rather than through the lexicon. A
    mission's own instructions are read from their words (as on a real vehicle: one naming a kind the
    scene lacks ends `target_not_found`)."""
    kind, attribute = targets[0]
    repeats = any(other_kind == kind for other_kind, _ in targets[1:])
    text = mission.instruction_text(kind, attribute, kind_repeats=repeats)
    return text, TargetQuery(kind, attribute if (mission.names_colour or repeats) else None)


@dataclass
class LoadedModels:
    """Models loaded once and shared by many missions in one process (benchmarks, suites), and the
    simulator kept warm between them.

    A mission that asks for the default image detector or the latent planner with
    this checkpoint uses these instead of loading its own.
    """

    detector: Detector | None = None
    latent: Planner | None = None
    latent_checkpoint: str | None = None
    detector_checkpoint: str | None = None
    """The checkpoint `detector` was loaded from (None: the shipped weights)."""
    simulators: WarmSimulators | None = None
    """A simulated MAVLink vehicle kept warm between the process's missions (`kits.warm`); None: each
    mission starts its own."""


def shared_models(missions: Sequence[Mission]) -> LoadedModels:
    """The models several missions flown in one process share, loaded once: the image detector of the
    first that uses one (a mission with another checkpoint loads its own), and the latent planner of the
    first that flies one (likewise)."""
    detector, detector_checkpoint = None, None
    first_image = next((m for m in missions if m.detector == "image"), None)
    if first_image is not None:
        from perception.image_detector import ImageDetector  # torch: loaded only when used

        detector_checkpoint = first_image.detector_checkpoint
        if detector_checkpoint is None:
            detector = ImageDetector.shipped()
        else:
            detector = ImageDetector.load(detector_checkpoint)
    latent = next((m for m in missions if m.planner == "latent"), None)
    planner = None if latent is None else make_planner("latent", checkpoint=latent.checkpoint)
    return LoadedModels(
        detector=detector,
        latent=planner,
        latent_checkpoint=latent and latent.checkpoint,
        detector_checkpoint=detector_checkpoint,
    )


def models_detector(mission: Mission, models: LoadedModels | None) -> Detector | None:
    """The shared image detector, when the mission asks for the image detector of the same checkpoint."""
    if models is None or mission.detector != "image":
        return None
    return models.detector if mission.detector_checkpoint == models.detector_checkpoint else None


def models_planner(mission: Mission, models: LoadedModels | None, truth: TruthProbe | None) -> Planner | None:
    """The shared latent planner, when the mission asks for it with the same checkpoint."""
    if models is None or mission.planner != "latent" or models.latent is None:
        return None
    return models.latent if mission.checkpoint == models.latent_checkpoint else None


def image_detector_for(mission: Mission, models: LoadedModels | None) -> Detector:
    """The mission's image detector: the shared one, its named checkpoint, or the shipped weights."""
    shared = models_detector(mission, models)
    if shared is not None:
        return shared
    from perception.image_detector import ImageDetector  # torch: loaded only when used

    if mission.detector_checkpoint is not None:
        return ImageDetector.load(mission.detector_checkpoint)
    return ImageDetector.shipped()


def planner_for(mission: Mission, models: LoadedModels | None, truth: TruthProbe | None) -> Planner:
    """The mission's planner: the shared latent one, or a new one (the oracle needs truth)."""
    return models_planner(mission, models, truth) or make_planner(
        mission.planner, checkpoint=mission.checkpoint, seed=mission.scene.seed, truth_offset=truth
    )
