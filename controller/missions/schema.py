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
instructions:                    # centred in order in ONE flight (take off once, land once); [] (the
  - centre the gauge             # default): one resolved from the scene, "center the <kind>" (with its
  - {instruction: the red valve, expect: {outcome: centred, max_steps: 8}}   # colour where needed)
# instruction: center the gauge  # one instruction: the same as a one-element `instructions` list
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

`instructions`: each entry is flown by its own run of the centring loop (its own step budget,
`max_steps`, and `timeout_s`) from where the previous one left the drone, holding in between; a plain
string is judged by the mission's `expect`, a mapping may give its own `expect` (replacing the
mission's for that instruction). The mission passes when every instruction meets its expectation.
An instruction whose target is not in view where the vehicle holds flies back to where the flight
started and looks again there (`return_to_start`); one that names a target the scene lacks, or one
not in view from there either, ends `target_not_found` and the flight goes on to the next. The
scene's named target (`target_kind`, `target_attribute`, `twins`) is the one the first instruction
names; the other targets are the scene's others.

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

from controller.missions.vehicles import (
    ARDUPILOT_SITL,
    MAVLINK_SIMULATED,
    PX4_SITL,
    SIM,
    SIM_MAVLINK,
    SIMULATED_VEHICLES,
)
from controller.planning.grounding import InstructionRefused, parse_instruction, understand
from controller.planning.loop_records import LoopSettings, Outcome
from controller.planning.planners import PLANNERS, PlannerName
from drone_inspect_core.config_files import ConfigFileError, Range, StrictModel, read_yaml, validate_mapping
from drone_inspect_core.own_kinds import checkpoint_kinds
from drone_inspect_core.sim_speed import parse_sim_speed
from drone_inspect_core.vocabulary import (
    Vocabulary,
    VocabularyError,
    load_glossary,
    shipped_vocabulary,
    validated_kinds,
    vocabulary_with,
)
from drone_inspect_core.world_options import CameraFaults, StartPose, WindConfig
from flight.errors import ConnectionUrlError
from flight.link_faults import LinkFaults
from flight.urls import validate_connection_url

DetectorName = Literal["image", "truth"]

_SIMULATED = ", ".join(map(repr, SIMULATED_VEHICLES))
_MAVLINK_SCHEMES = ("udp://", "udpin://", "udpout://", "tcp://", "tcpin://", "tcpout://", "serial://")
_STREAM_SCHEMES = ("http://", "https://", "rtsp://", "file://")


AutopilotName = Literal["auto", "px4", "ardupilot"]
"""A MAVLink URL's autopilot (`Mission.autopilot`): "auto" (told by its HEARTBEAT), "px4" (flown with
MAVSDK) or "ardupilot" (flown in GUIDED mode, `flight.ardupilot.vehicle`)."""


class PortSpec(StrictModel):
    """Ports for a `sim-mavlink` mission: "auto" (the default) takes free ones per run, so any number of
    runs fly at once; a number fixes one (UDP p: the sim-vehicle, p+1: the .tlog relay, p+2: MAVSDK),
    checked free before anything starts (`drone_inspect_core.ports.check_free`)."""

    mavlink_udp: int | Literal["auto"] = "auto"
    http: int | Literal["auto"] = "auto"

    @field_validator("mavlink_udp", "http")
    @classmethod
    def _port_range(cls, value: int | str) -> int | str:
        if isinstance(value, int) and not 1024 <= value <= 65533:
            raise ValueError(f"must be a port in 1024..65533 or 'auto', got {value}")
        return value


class SitlSpec(StrictModel):
    """What a mission flown by a real autopilot's SITL (PX4, ArduPilot) says about running it."""

    dir: str | None = None
    """The autopilot's SITL folder; None: the command line's option, else its environment variable."""
    instance: int | Literal["auto"] = "auto"
    """Instance 0..9 (the autopilot's ports shift with it); "auto": the lowest one nobody holds."""
    speed: float | Literal["max"] = 1.0
    """Simulated seconds per wall second, or "max" (lockstep as fast as it goes; benchmarks)."""
    params: dict[str, float] = Field(default_factory=dict)
    """Autopilot parameters set at boot (`MPC_XY_VEL_MAX: 1.0`, `WPNAV_SPEED: 300`)."""

    @field_validator("instance")
    @classmethod
    def _instance_range(cls, value: int | str) -> int | str:
        if isinstance(value, int) and not 0 <= value <= 9:
            raise ValueError(f"must be 0..9 or 'auto', got {value}")
        return value

    @field_validator("speed")
    @classmethod
    def _speed_range(cls, value: float | str) -> float | str:
        if isinstance(value, float) and not 0.05 <= value <= 100.0:
            raise ValueError(f"must be in [0.05, 100] or 'max', got {value:g}")
        return value


class Px4Spec(SitlSpec):
    """How a `px4-sitl` mission runs PX4 SITL (see `sim_world.px4_bridge`; ports 4560+N, 14540+N)."""

    noise: float = Field(default=1.0, gt=0.0, le=10.0)
    """Scale of every sensor noise and bias (PX4 refuses perfectly constant sensors: > 0)."""
    keep_ulog: bool = True
    """Copy PX4's .ulg flight log into the report folder (`px4/`); ~4 MB per 20 s."""


class ArduPilotSpec(SitlSpec):
    """How an `ardupilot-sitl` mission runs ArduCopter SITL (see `sim_world.ardupilot_bridge`; ports
    9002+10N, 5760+10N). Its folder: `--ardupilot`, else $ARDUPILOT_SITL_DIR, else
    ../shared/ardupilot-sitl."""

    noise: float = Field(default=1.0, ge=0.0, le=10.0)
    """Scale of the IMU noise and bias the bridge adds (0: none; ArduPilot simulates GPS, baro, compass)."""
    keep_logs: bool = True
    """Copy ArduPilot's .BIN flight logs into the report folder (`ardupilot/`); ~1 MB per simulated min."""
    hold_mode: Literal["BRAKE", "LOITER"] = "BRAKE"
    """The mode that holds after takeoff and outside offboard (LOITER follows the pilot's throttle)."""


class FaultSpec(StrictModel):
    """Faults injected on purpose, to see how a mission degrades; all off by default."""

    link: LinkFaults | None = None
    """A bad MAVLink link between the controller and the vehicle (`flight.link_faults`)."""
    camera: CameraFaults | None = None
    """A bad camera at its source (`drone_inspect_core.world_options`); times: simulated s from boot."""
    gust_m_s: float = Field(default=0.0, ge=0.0, le=10.0)
    """Gusts (the wind's standard deviation per axis, m/s) in a simulated world."""
    vehicle_dies_at_s: float | None = Field(default=None, ge=0.0)
    """The simulated vehicle (sim-vehicle, or PX4 itself) is killed at this simulated time from boot."""
    seed: int = Field(default=0, ge=0)

    def link_faults(self) -> LinkFaults | None:
        """The link faults for the relay, seeded with this mission's `seed` (None: a clean link)."""
        return None if self.link is None else self.link.model_copy(update={"seed": self.seed})

    def camera_faults(self) -> CameraFaults | None:
        """The camera faults for the video source, seeded with this mission's `seed`."""
        return None if self.camera is None else self.camera.model_copy(update={"seed": self.seed})

    @property
    def any(self) -> bool:
        return bool(self.link or self.camera or self.gust_m_s or self.vehicle_dies_at_s is not None)


class MissionFileError(ConfigFileError):
    """A mission file that cannot be flown; the message names the file and the field."""


class SceneSpec(StrictModel):
    """Which scene: a scene config (a YAML path, an inline mapping, or null for the default) and a seed."""

    config: str | dict[str, Any] | None = None
    seed: int = Field(default=0, ge=0)


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

    def draw(self, hfov_deg: float, vfov_deg: float) -> StartPose:
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
        return StartPose(right_m=right_m, up_m=up_m, distance_m=distance, yaw_deg=yaw)


class RandomStartSpec(StrictModel):
    random: RandomStart


def _start_form(value: object) -> str:
    random = isinstance(value, RandomStartSpec) or (isinstance(value, dict) and "random" in value)
    return "random-start" if random else "fixed-start"


Start = Annotated[
    Annotated[StartPose, Tag("fixed-start")] | Annotated[RandomStartSpec, Tag("random-start")],
    Discriminator(_start_form),
]
"""Either a fixed offset or `{random: {...}}`; errors are reported for the form that was written."""


class Expectations(StrictModel):
    """What must hold when the loop ends; an unset limit is not checked.

    With `outcome: centred` (the default) the target must also end within ε of the
    image centre per simulator truth (per the detector where there is no truth).
    """

    outcome: Outcome = Outcome.CENTRED
    max_steps: int | None = Field(default=None, ge=0)
    final_offset_px: float | None = Field(default=None, gt=0.0)
    """The final truth offset, max(|du|, |dv|), must not exceed this."""


class MissionInstruction(StrictModel):
    """One instruction of a mission's flight, and what must hold when its centring loop ends."""

    instruction: str = Field(min_length=1)
    expect: Expectations | None = None
    """None: the mission's `expect`."""


class Mission(StrictModel):
    """One centring mission: one flight, one or more instructions."""

    name: str = Field(min_length=1, pattern=r"^[A-Za-z0-9_.-]+$")
    tags: tuple[str, ...] = ()
    description: str = ""
    glossary: str | dict[str, str] | None = None
    """A site's own words for the kinds (`{manometer: gauge}`, or a glossary file, relative to the mission
    file): the instruction may use them, and the planner hears the kind's trained noun."""
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
    start: Start = StartPose()
    instructions: tuple[MissionInstruction, ...] = ()
    """What to centre, in order, in one flight (the module docstring). Empty: one instruction resolved
    from the built scene, "center the <kind>" ("center the <colour> <kind>" when the colour tells the
    named target apart: twins, or a `target_attribute`). A file's `instruction: TEXT` is `[TEXT]`."""
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
    return_to_start: bool = True
    """An instruction whose target is not in view where the vehicle holds (a flight of several: the last
    one left it elsewhere) flies back across the wall to where the flight started, and looks again there,
    before it ends `target_not_found`. The start is where the operator set up the view of the wall."""
    takeoff_altitude_m: float = Field(default=1.5, gt=0.3, le=4.0)
    wind: WindConfig | None = None
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

    @model_validator(mode="before")
    @classmethod
    def _one_instruction(cls, data: object) -> object:
        """`instruction: TEXT` is `instructions: [TEXT]` (`instruction: null`: none given); both at once
        only where `instruction` is null (the command line's `--instruction` over a file's)."""
        if not isinstance(data, dict) or "instruction" not in data:
            return data
        data = dict(data)
        one = data.pop("instruction")
        if one is not None and data.get("instructions"):
            raise ValueError("instruction: give `instruction` (one) or `instructions` (a list), not both")
        if one is not None:
            data["instructions"] = [one]
        return data

    @field_validator("instructions", mode="before")
    @classmethod
    def _plain_instructions(cls, value: object) -> object:
        """A plain string entry is `{instruction: TEXT}` (judged by the mission's `expect`)."""
        if isinstance(value, list | tuple):
            return [{"instruction": v} if isinstance(v, str) else v for v in value]
        return value

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
        return vocabulary_with(inline or {}, self.kinds, self.model_kinds()).with_glossary(
            self.glossary_words()
        )

    def model_kinds(self) -> dict[str, dict[str, Any]]:
        """The kinds the mission's detector and planner checkpoints were trained on beyond the shipped ones
        (their `config.json`'s `kinds`, words only): a mission may name a kind its models know."""
        merged: dict[str, dict[str, Any]] = {}
        for folder in (self.detector_checkpoint, self.checkpoint):
            if folder is not None:
                merged.update(checkpoint_kinds(folder))
        return merged

    def glossary_words(self) -> dict[str, str]:
        """The glossary's `phrase: kind` mapping (read from its file when it names one)."""
        if self.glossary is None:
            return {}
        return load_glossary(self.glossary) if isinstance(self.glossary, str) else dict(self.glossary)

    @field_validator("glossary", mode="before")
    @classmethod
    def _glossary_file(cls, value: object, info: ValidationInfo) -> object:
        """A glossary file is found relative to the mission file, and read now: a bad one is named."""
        if isinstance(value, str):
            base_dir = (info.context or {}).get("base_dir")
            path = Path(value).expanduser()
            value = str(path if path.is_absolute() or base_dir is None else base_dir / path)
            try:
                load_glossary(value)
            except VocabularyError as exc:
                raise ValueError(str(exc)) from None
        return value

    @model_validator(mode="after")
    def _known_kind(self) -> Mission:
        try:
            vocabulary = self.vocabulary  # the glossary's kinds are checked here
        except VocabularyError as exc:
            raise ValueError(f"glossary: {exc}") from None
        if self.target_kind is not None and not isinstance(self.scene.config, str):
            try:
                vocabulary.kind(self.target_kind)
            except VocabularyError as exc:
                raise ValueError(f"target_kind: {exc}") from None
        if not isinstance(self.scene.config, str):  # (a scene file's own kinds join when its scene is
            for field, text in self._instruction_fields():  # built; the session checks again then)
                try:
                    understand(text, vocabulary)
                except InstructionRefused as exc:
                    raise ValueError(f"{field}: {exc}") from None
        return self

    def _instruction_fields(self) -> list[tuple[str, str]]:
        """(the field as errors name it, the text) of each instruction."""
        if len(self.instructions) == 1:
            return [("instruction", self.instructions[0].instruction)]
        return [(f"instructions[{i}]", entry.instruction) for i, entry in enumerate(self.instructions)]

    @model_validator(mode="after")
    def _named_target(self) -> Mission:
        """Twins need a second target, and the first instruction (the named target's) must tell the twins
        apart by colour."""
        if self.twins and self.targets < 2:
            raise ValueError(
                f"twins: needs targets >= 2 (the named one and its twin), got targets {self.targets}"
            )
        if self.instructions and (self.twins or self.target_attribute is not None):
            field, text = self._instruction_fields()[0]
            named = parse_instruction(text, self.vocabulary).attribute
            if named is None and self.twins:
                raise ValueError(
                    f"{field}: {text!r} names no colour, but the scene has twins "
                    "(two targets of one kind): say which, e.g. 'center the red gauge'"
                )
            if self.target_attribute is not None and named not in (None, self.target_attribute):
                raise ValueError(
                    f"{field}: {text!r} names {named}, but target_attribute is {self.target_attribute}"
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
        if self.detector == "truth" and len(self.instructions) > 1:
            raise ValueError(
                "detector: 'truth' sees the scene's named target only; several instructions need the image "
                "detector (detector: image)"
            )
        if self.vehicle not in (SIM, PX4_SITL, ARDUPILOT_SITL) and self.wind is not None:
            raise ValueError("wind: only the worlds of 'sim', 'px4-sitl' and 'ardupilot-sitl' simulate wind")
        mavlink_sim = self.vehicle in MAVLINK_SIMULATED
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
        """The instruction resolved from the built scene's named target (for a mission that gives none): its
        kind, and its trim colour `attribute` where `names_colour` or another target has the same kind
        (`kind_repeats`)."""
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
