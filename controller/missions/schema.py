"""The mission file: one centring flight, what it starts from and what must hold at the end.

A mission is a YAML file validated on load (pydantic, unknown keys refused). A bad
file is refused with a `MissionFileError` that names the file and the field
(`missions/x.yaml: start.distance_m: Input should be greater than 0`), never with a
traceback from inside pydantic or PyYAML.

```yaml
name: sector-ne                  # required; used for the report folder
tags: [sector, quick]
scene: {seed: 1001}              # or {config: scenes/x.yaml, seed: 3}, or {config: {...inline...}, seed: 3}
kinds: {}                        # your own: {flange: {image: f.png, size_m: [0.3, 0.3], words: [flange]}}
target_kind: gauge               # gauge | valve | switchbox | a kind of yours | null (the scene draws one)
targets: 1                       # 1..4 targets on the wall, the named one included
twins: false                     # one other target of the named kind, in another trim colour (targets >= 2)
target_attribute: null           # the named target's trim colour: black | grey | red | blue | yellow | null
start: {right_m: -0.5, up_m: -0.4, distance_m: 2.0, yaw_deg: 0}   # drone pose relative to the centred pose
# start: {random: {seed: 7, view_fraction: [0.2, 0.8], distance_m: [1.6, 2.6], yaw_deg: [-8, 8]}}
instruction: center the gauge     # null: "center the <kind>", "center the <colour> <kind>" with twins
vehicle: sim                     # sim | sim-mavlink | px4-sitl | ardupilot-sitl | a MAVLink URL (udpin://...)
autopilot: auto                  # a URL's autopilot: auto (its HEARTBEAT) | px4 (MAVSDK) | ardupilot
camera: sim                      # sim | a stream URL (http://host:8080/stream.mjpg, rtsp://...)
planner: latent                  # latent | classic | random | oracle
checkpoint: null                 # null: the shipped one
detector: image                  # image | truth (in-process sim only, for debugging)
epsilon_px: null                 # null: default_epsilon_px(image width)
stop_margin_px: null             # stop at ε − this per detector; null: 2 px at 224 px width, scaled
max_steps: 20
timeout_s: 120
wind: {mean_enu_m_s: [0.3, 0, 0], gust_std_m_s: 0.2}
loop: {max_move_m: 1.0}          # the loop's settings (move scheme, refinement budget, ...): LoopSettings
expect: {outcome: centred, max_steps: 12, final_offset_px: 10}
sim_speed: 1.0                   # vehicle: sim-mavlink only: simulated s per wall s, or max
px4: {instance: auto, speed: 1.0}  # vehicle: px4-sitl only (the PX4 folder: --px4 or $PX4_SITL_DIR)
ardupilot: {instance: auto, speed: 1.0}  # vehicle: ardupilot-sitl only (--ardupilot, $ARDUPILOT_SITL_DIR)
```

`start` is the drone's pose relative to the pose that centres the target (in front
of it, looking at the wall): `right_m` > 0 puts the drone to the right of that pose, so
the target appears left of the image centre. A random start draws the target's
image position as a fraction of the half view (`view_fraction`, in any direction),
so a random start always has the target in view.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import (
    Discriminator,
    Field,
    Tag,
    ValidationInfo,
    field_validator,
    model_validator,
)

from controller.missions.schema_specs import ArduPilotSpec, AutopilotName, FaultSpec, PortSpec, Px4Spec
from controller.planning.grounding import parse_instruction
from controller.planning.loop_records import LoopSettings, Outcome
from controller.planning.planners import PLANNERS, PlannerName
from drone_inspect_core.config_files import ConfigFileError, Range, StrictModel, read_yaml, validate_mapping
from drone_inspect_core.sim_speed import parse_sim_speed
from drone_inspect_core.vocabulary import (
    Vocabulary,
    VocabularyError,
    shipped_vocabulary,
    validated_kinds,
    vocabulary_with,
)
from flight.errors import ConnectionUrlError
from flight.urls import validate_connection_url

DetectorName = Literal["image", "truth"]

SIM = "sim"
SIM_MAVLINK = "sim-mavlink"
PX4_SITL = "px4-sitl"
ARDUPILOT_SITL = "ardupilot-sitl"
SIMULATED_VEHICLES = (SIM, SIM_MAVLINK, ARDUPILOT_SITL, PX4_SITL)
_SIMULATED = ", ".join(map(repr, SIMULATED_VEHICLES))
_MAVLINK_SCHEMES = ("udp://", "udpin://", "udpout://", "tcp://", "tcpin://", "tcpout://", "serial://")
_STREAM_SCHEMES = ("http://", "https://", "rtsp://", "file://")


class MissionFileError(ConfigFileError):
    """A mission file that cannot be flown; the message names the file and the field."""


class SceneSpec(StrictModel):
    """Which scene: a scene config (a YAML path, an inline mapping, or null for the default) and a seed."""

    config: str | dict[str, Any] | None = None
    seed: int = Field(default=0, ge=0)


class StartOffset(StrictModel):
    """A fixed start: the drone's offset from the centred pose, in metres and degrees."""

    right_m: float = Field(default=0.0, ge=-3.0, le=3.0)
    up_m: float = Field(default=0.0, ge=-2.0, le=2.0)
    distance_m: float = Field(default=2.0, gt=0.5, le=6.0)
    yaw_deg: float = Field(default=0.0, ge=-30.0, le=30.0)


class RandomStart(StrictModel):
    """A seeded random start: the target's image position as a fraction of the half view, any direction."""

    seed: int = Field(ge=0)
    view_fraction: Range = (0.15, 0.8)
    distance_m: Range = (1.6, 2.6)
    yaw_deg: Range = (-8.0, 8.0)

    @field_validator("view_fraction")
    @classmethod
    def _inside_the_view(cls, value: tuple[float, float]) -> tuple[float, float]:
        if not (value[0] >= 0.0 and value[1] < 1.0):
            raise ValueError(f"must lie within [0, 1), got {list(value)}")
        return value

    @field_validator("distance_m")
    @classmethod
    def _off_the_wall(cls, value: tuple[float, float]) -> tuple[float, float]:
        if value[0] <= 0.5:
            raise ValueError(f"must stay above 0.5 m, got {list(value)}")
        return value

    def draw(self, hfov_deg: float, vfov_deg: float) -> StartOffset:
        """The start offset this seed gives, for a level camera with these fields of view.

        The target is put at image position (fu, fv) (fractions of the half width and
        height; u right, v down) from a drone `distance` from the wall, yawed `yaw`
        clockwise: the target's bearing from the wall normal is the bearing in the
        image plus the yaw, and its height offset scales with the depth along the
        optical axis.
        """
        rng = np.random.default_rng(self.seed)
        fraction = rng.uniform(*self.view_fraction)
        angle = rng.uniform(0.0, 2.0 * math.pi)
        distance = rng.uniform(*self.distance_m)
        yaw = rng.uniform(*self.yaw_deg)
        fu, fv = fraction * math.cos(angle), fraction * math.sin(angle)
        bearing = math.atan(fu * math.tan(math.radians(hfov_deg) / 2.0))  # in the image, right positive
        depth = distance * math.cos(bearing) / math.cos(bearing + math.radians(yaw))  # along the optical axis
        right_m = -distance * math.tan(bearing + math.radians(yaw))
        up_m = fv * depth * math.tan(math.radians(vfov_deg) / 2.0)
        return StartOffset(right_m=right_m, up_m=up_m, distance_m=distance, yaw_deg=yaw)


class RandomStartSpec(StrictModel):
    random: RandomStart


def _start_form(value: object) -> str:
    random = isinstance(value, RandomStartSpec) or (isinstance(value, dict) and "random" in value)
    return "random-start" if random else "fixed-start"


Start = Annotated[
    Annotated[StartOffset, Tag("fixed-start")] | Annotated[RandomStartSpec, Tag("random-start")],
    Discriminator(_start_form),
]
"""Either a fixed offset or `{random: {...}}`; errors are reported for the form that was written."""


class WindSpec(StrictModel):
    """Wind for the simulated world (ENU m/s); ignored, with a warning, for a real vehicle."""

    mean_enu_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    gust_std_m_s: float = Field(default=0.0, ge=0.0, le=5.0)
    gust_time_constant_s: float = Field(default=2.0, gt=0.0)


class Expectations(StrictModel):
    """What must hold when the loop ends; an unset limit is not checked.

    With `outcome: centred` (the default) the target must also end within ε of the
    image centre per simulator truth (per the detector where there is no truth).
    """

    outcome: Outcome = Outcome.CENTRED
    max_steps: int | None = Field(default=None, ge=0)
    final_offset_px: float | None = Field(default=None, gt=0.0)
    """The final truth offset, max(|du|, |dv|), must not exceed this."""


class Mission(StrictModel):
    """One centring mission."""

    name: str = Field(min_length=1, pattern=r"^[A-Za-z0-9_.-]+$")
    tags: tuple[str, ...] = ()
    description: str = ""
    kinds: dict[str, dict[str, Any]] = Field(default_factory=dict)
    """Target kinds the mission adds (`drone_inspect_core.vocabulary.parse_kind`; images relative to the
    mission file): the scene may draw them, the instruction may name them."""
    scene: SceneSpec = SceneSpec()
    target_kind: str | None = None
    """The named target's kind (shipped, or the mission's or its inline scene's own); None: drawn."""
    targets: int = Field(default=1, ge=1, le=4)
    """Targets on the wall, the named one (the one to centre) included."""
    twins: bool = False
    """One other target has the named target's kind, in another trim colour (needs targets >= 2)."""
    target_attribute: str | None = None
    """The named target's trim colour (a colour name of `drone_inspect_core.vocabulary`);
    None: drawn."""
    start: Start = StartOffset()
    instruction: str | None = None
    """None: resolved from the built scene, "center the <kind>" ("center the <colour> <kind>" when the
    colour tells the named target apart: twins, or a `target_attribute`)."""
    vehicle: str = SIM
    camera: str = SIM
    planner: PlannerName = "latent"
    checkpoint: str | None = None
    detector: DetectorName = "image"
    """`image`: the image detector (what a real drone has); `truth`: simulator truth (debugging only)."""
    detector_checkpoint: str | None = None
    """None: the image detector's shipped weights."""
    epsilon_px: float | None = Field(default=None, gt=0.0)
    stop_margin_px: float | None = Field(default=None, ge=0.0)
    """The loop stops at ε − this per detector (None: 2 px at 224 px width, scaled); must be < ε."""
    max_steps: int = Field(default=20, ge=1, le=500)
    timeout_s: float = Field(default=120.0, gt=0.0)
    takeoff_altitude_m: float = Field(default=1.5, gt=0.3, le=4.0)
    wind: WindSpec | None = None
    loop: LoopSettings = LoopSettings()
    """How the centring loop moves and waits (`controller.planning.loop_records.LoopSettings`)."""
    expect: Expectations = Expectations()
    ports: PortSpec = PortSpec()
    sim_speed: float | Literal["max"] = 1.0
    """sim-mavlink: the sim-vehicle's speed (`sim_world.vehicle.config.parse_sim_speed`); the controller
    then times its moves on the vehicle's clock."""
    px4: Px4Spec = Px4Spec()
    ardupilot: ArduPilotSpec = ArduPilotSpec()
    autopilot: AutopilotName = "auto"
    faults: FaultSpec = FaultSpec()

    @field_validator("sim_speed", mode="before")
    @classmethod
    def _sim_speed(cls, value: float | str) -> float | str:
        return parse_sim_speed(value)

    @field_validator("kinds", mode="before")
    @classmethod
    def _kinds(cls, value: object, info: ValidationInfo) -> object:
        return validated_kinds(value, (info.context or {}).get("base_dir"))

    @field_validator("target_attribute")
    @classmethod
    def _known_colour(cls, value: str | None) -> str | None:
        colours = shipped_vocabulary().colour_names
        if value is not None and value not in colours:
            raise ValueError(f"must be one of {', '.join(colours)} or null, got {value!r}")
        return value

    @property
    def vocabulary(self) -> Vocabulary:
        """The shipped vocabulary, with the kinds of an inline scene config and of the mission itself (a
        scene file's own kinds join when the scene is built: `controller.missions.setup`)."""
        inline = self.scene.config.get("kinds") if isinstance(self.scene.config, dict) else None
        return vocabulary_with(inline or {}, self.kinds)

    @model_validator(mode="after")
    def _known_kind(self) -> Mission:
        if self.target_kind is not None and not isinstance(self.scene.config, str):
            try:
                self.vocabulary.kind(self.target_kind)
            except VocabularyError as exc:
                raise ValueError(f"target_kind: {exc}") from None
        return self

    @model_validator(mode="after")
    def _named_target(self) -> Mission:
        """Twins need a second target, and an instruction that tells the twins apart by colour."""
        if self.twins and self.targets < 2:
            raise ValueError(
                f"twins: needs targets >= 2 (the named one and its twin), got targets {self.targets}"
            )
        if self.instruction is not None and (self.twins or self.target_attribute is not None):
            named = parse_instruction(self.instruction, self.vocabulary).attribute
            if named is None and self.twins:
                raise ValueError(
                    f"instruction: {self.instruction!r} names no colour, but the scene has twins "
                    "(two targets of one kind): say which, e.g. 'center the red gauge'"
                )
            if self.target_attribute is not None and named not in (None, self.target_attribute):
                raise ValueError(
                    f"instruction: {self.instruction!r} names {named}, but target_attribute is "
                    f"{self.target_attribute}"
                )
        return self

    @model_validator(mode="after")
    def _links(self) -> Mission:
        if (
            self.stop_margin_px is not None
            and self.epsilon_px is not None
            and self.stop_margin_px >= self.epsilon_px
        ):
            raise ValueError(
                f"stop_margin_px: {self.stop_margin_px:g} must be smaller than epsilon_px {self.epsilon_px:g}"
            )
        if self.vehicle not in SIMULATED_VEHICLES and not self.vehicle.startswith(_MAVLINK_SCHEMES):
            raise ValueError(
                f"vehicle: {self.vehicle!r} is neither {_SIMULATED} nor a MAVLink URL "
                f"({', '.join(s + '...' for s in _MAVLINK_SCHEMES)})"
            )
        if self.is_real:
            try:
                validate_connection_url(self.vehicle)
            except ConnectionUrlError as exc:
                raise ValueError(f"vehicle: {exc.detail}") from None
        if self.camera != SIM and not self.camera.startswith(_STREAM_SCHEMES):
            raise ValueError(
                f"camera: {self.camera!r} is neither 'sim' nor a stream URL "
                f"({', '.join(s + '...' for s in _STREAM_SCHEMES)})"
            )
        if self.is_real and self.camera == SIM:
            raise ValueError("camera: a real vehicle needs a stream URL, not 'sim'")
        if not self.is_real and self.camera != SIM:
            raise ValueError(
                f"camera: the simulated vehicle {self.vehicle!r} streams its own camera; use camera: sim "
                "(a camera URL goes with a real vehicle's MAVLink URL)"
            )
        if self.sim_speed != 1.0 and self.vehicle != SIM_MAVLINK:
            raise ValueError(
                f"sim_speed: goes with vehicle sim-mavlink, not {self.vehicle!r} (SITL: px4/ardupilot.speed)"
            )
        if self.is_real and self.detector == "truth":
            raise ValueError("detector: 'truth' needs the simulator; a real vehicle uses the image detector")
        if self.vehicle != SIM and self.detector == "truth":
            raise ValueError("detector: 'truth' is available in the in-process sim only (vehicle: sim)")
        if self.vehicle not in (SIM, PX4_SITL, ARDUPILOT_SITL) and self.wind is not None:
            raise ValueError("wind: only the worlds of 'sim', 'px4-sitl' and 'ardupilot-sitl' simulate wind")
        mavlink_sim = self.vehicle in (SIM_MAVLINK, PX4_SITL, ARDUPILOT_SITL)
        if self.faults.link is not None and not (mavlink_sim or self.vehicle.startswith("udpin://")):
            raise ValueError(
                "faults.link: needs a relayed MAVLink link: sim-mavlink, a SITL vehicle or a udpin:// URL"
            )
        if (self.faults.camera is not None or self.faults.vehicle_dies_at_s is not None) and not mavlink_sim:
            raise ValueError(
                "faults: camera faults and a dying vehicle: ardupilot-sitl, sim-mavlink and px4-sitl only"
            )
        if self.faults.gust_m_s and self.is_real:
            raise ValueError("faults.gust_m_s: only a simulated world has wind to make gusty")
        for key, sitl in (("px4", PX4_SITL), ("ardupilot", ARDUPILOT_SITL)):
            if self.vehicle != sitl and key in self.model_fields_set:
                raise ValueError(f"{key}: only a '{sitl}' mission runs it (vehicle is {self.vehicle!r})")
        if not self.is_real and self.autopilot != "auto":
            raise ValueError(f"autopilot: goes with a MAVLink URL; {self.vehicle!r} knows its own autopilot")
        if self.is_real and PLANNERS[self.planner].needs_truth:
            raise ValueError(
                f"planner: {self.planner!r} needs simulator truth, which a real vehicle does not have"
            )
        return self

    @property
    def is_real(self) -> bool:
        """Flown on a vehicle at a URL: no simulator, no truth."""
        return self.vehicle not in SIMULATED_VEHICLES

    def with_seed(self, seed: int) -> Mission:
        """The same mission in scene `seed` (a random start is redrawn from the same seed)."""
        update: dict[str, Any] = {"scene": self.scene.model_copy(update={"seed": seed})}
        if isinstance(self.start, RandomStartSpec):
            update["start"] = RandomStartSpec(random=self.start.random.model_copy(update={"seed": seed}))
        return self.model_copy(update=update)

    @property
    def names_colour(self) -> bool:
        """Whether a resolved instruction names the target's colour (twins, or a `target_attribute`)."""
        return self.twins or self.target_attribute is not None

    def instruction_text(
        self, target_kind: str | None, attribute: str | None = None, kind_repeats: bool = False
    ) -> str:
        """The instruction, or one resolved from the built scene's named target: its kind, and its trim
        colour `attribute` where `names_colour` or another target has the same kind (`kind_repeats`)."""
        if self.instruction:
            return self.instruction
        colour = f"{attribute} " if attribute and (self.names_colour or kind_repeats) else ""
        return f"center the {colour}{target_kind or 'target'}"


_UNNAMED = ("fixed-start", "random-start")  # the `start` union's tags: not fields


def parse_mission(
    data: object, source: str | Path = "<mission>", overrides: dict[str, Any] | None = None
) -> Mission:
    """Validate a parsed mapping (with top-level `overrides` applied); errors name `source` and the field."""
    if not isinstance(data, dict):
        kind = type(data).__name__
        raise MissionFileError(source, None, f"expected a mapping at the top level, got {kind}")
    base_dir = Path(source).parent if isinstance(source, Path) else None
    return validate_mapping(
        Mission, {**data, **(overrides or {})}, source, MissionFileError, _UNNAMED, {"base_dir": base_dir}
    )


def load_mission(path: str | Path, overrides: dict[str, Any] | None = None) -> Mission:
    """Read and validate a mission YAML file (see the module docstring for its fields)."""
    path = Path(path)
    data = read_yaml(path, MissionFileError)
    mission = parse_mission(data, path)  # the file alone first: its own errors name the file
    if overrides:  # then the command line's changes, whose errors name the command line
        source = f"command-line options over {path}"
        base_dir = path.parent
        mission = validate_mapping(
            Mission, {**data, **overrides}, source, MissionFileError, _UNNAMED, {"base_dir": base_dir}
        )
    if isinstance(mission.scene.config, str) and not Path(mission.scene.config).is_absolute():
        # A scene file is found relative to the mission file, so a suite folder can be moved as a whole.
        resolved = (path.parent / mission.scene.config).resolve()
        mission = mission.model_copy(
            update={"scene": mission.scene.model_copy(update={"config": str(resolved)})}
        )
    return mission
