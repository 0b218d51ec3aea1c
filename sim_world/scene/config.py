"""The scene config: what the inspection scene may look like, as ranges to draw from.

Every randomised quantity is a `[min, max]` range (or a list of choices) so that one
YAML file describes a whole family of scenes; `Scene.build(client, config, seed)` draws
one member of the family. A file is validated on load and a bad one is refused with a
`SceneConfigError` that names the file and the field (`scenes/bad.yaml: target.size_m:
min 0.5 > max 0.2`), never with a traceback from inside pydantic or PyYAML.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import AfterValidator, Field, ValidationInfo, field_validator, model_validator

from drone_inspect_core.config_files import (
    ConfigFileError,
    StrictModel,
    check_range,
    read_yaml,
    validate_mapping,
)
from drone_inspect_core.vocabulary import Vocabulary, shipped_vocabulary, validated_kinds, vocabulary_with

WallTexture = Literal["concrete", "brick", "painted_metal"]
FloorTexture = Literal["concrete", "tiles", "grating"]
DistractorKind = Literal["dial", "box", "sign"]

TARGET_KINDS: tuple[str, ...] = shipped_vocabulary().kind_names
"""The shipped kinds (`drone_inspect_core.vocabulary`): the default choices of a scene's targets."""
MAX_TARGETS = 4
"""The most targets one scene holds (all of them in view from the named target's centred pose)."""

_HEX_COLOUR = re.compile(r"^#[0-9a-fA-F]{6}$")


class SceneConfigError(ConfigFileError):
    """A scene file that cannot be used; the message names the file and the field."""


def _within(value: tuple[float, float], lo: float, hi: float) -> tuple[float, float]:
    """A range's check that both ends lie in [lo, hi] (use inside a field validator)."""
    if value[0] < lo or value[1] > hi:
        raise ValueError(f"must lie within [{lo:g}, {hi:g}], got [{value[0]:g}, {value[1]:g}]")
    return value


def _check_colour(value: str) -> str:
    if not _HEX_COLOUR.match(value):
        raise ValueError(f"{value!r} is not a colour of the form '#rrggbb'")
    return value.lower()


Range = Annotated[tuple[float, float], AfterValidator(check_range)]
"""A closed interval `[min, max]` to draw a value from uniformly; `[x, x]` fixes it."""
IntRange = Annotated[tuple[int, int], AfterValidator(check_range)]
"""An inclusive integer interval `[min, max]`."""
Colour = Annotated[str, AfterValidator(_check_colour)]
"""An sRGB colour as `'#rrggbb'`."""


def hex_to_rgb(colour: str) -> tuple[int, int, int]:
    """`'#rrggbb'` to an (r, g, b) tuple of 0..255 integers."""
    return int(colour[1:3], 16), int(colour[3:5], 16), int(colour[5:7], 16)


class TargetConfig(StrictModel):
    """The inspection targets: how many, which kinds, how big, where on the wall, in which colours.

    The first target is the *named* one (what an instruction asks to centre); the others
    stand beside it. Targets of one kind always differ in their trim colour's name
    (`drone_inspect_core.vocabulary.colour_name` of `bezel_colours`), the attribute an instruction names.
    """

    kinds: tuple[str, ...] = Field(default=TARGET_KINDS, min_length=1)
    """Choices for the named target's kind."""
    size_m: Range = (0.26, 0.40)
    """Gauge and handwheel diameter, switch-box width."""
    height_m: Range = (1.1, 1.9)
    """Height of the target's centre above the floor."""
    east_m: Range = (-1.0, 1.0)
    """East position of the target's centre on the wall."""
    dial_colours: tuple[Colour, ...] = Field(
        default=("#f4f1e8", "#ffffff", "#e9edf2", "#f7efd2"), min_length=1
    )
    """Gauge dial face, handwheel paint and switch-box enclosure colours are drawn from these."""
    bezel_colours: tuple[Colour, ...] = Field(
        default=("#2b2b2b", "#a8acb0", "#c0392b", "#1f4e8c", "#d4a017"), min_length=1
    )
    """Gauge bezel ring / case, handwheel hub and switch-box door frame colours."""
    needle_fraction: Range = (0.1, 0.9)
    """Gauge reading as a fraction of full scale."""
    other_kinds: tuple[str, ...] = Field(default=TARGET_KINDS, min_length=1)
    """Choices for the other targets' kinds (kinds not yet on the wall are preferred)."""
    twins: bool = False
    """With 2 or more targets: one other target has the named target's kind, in another trim colour."""
    attribute: str | None = None
    """The named target's trim colour name (`drone_inspect_core.vocabulary`): its trim is drawn from the
    `bezel_colours` of that name (that colour itself if none has it); None: from all of them."""
    count: IntRange = (1, 1)
    """How many targets on the wall (named one included), 1..4. Last, so that its check sees the rest."""

    @field_validator("kinds", "other_kinds", mode="before")
    @classmethod
    def _one_kind_is_a_list(cls, value: object) -> object:
        return (value,) if isinstance(value, str) else value

    @field_validator("count")
    @classmethod
    def _target_count(cls, value: tuple[int, int], info: ValidationInfo) -> tuple[int, int]:
        """1..4, and enough (kind, trim colour name) pairs to tell that many targets apart."""
        _within(value, 1, MAX_TARGETS)
        if not {"kinds", "other_kinds", "twins", "bezel_colours"} <= info.data.keys():
            return value  # another field is already refused
        names = len({shipped_vocabulary().colour_name(c) for c in info.data["bezel_colours"]})
        twins = info.data["twins"]
        if twins and value[1] >= 2 and names < 2:
            raise ValueError("twins need at least 2 bezel_colours with different colour names")
        for kind in info.data["kinds"]:
            others = set(info.data["other_kinds"]) | ({kind} if twins else set())
            pairs = len(others) * names - (1 if kind in others else 0)
            if pairs < value[1] - 1:
                raise ValueError(
                    f"up to {value[1]} targets must differ in kind or bezel colour name, but a named "
                    f"{kind} leaves {pairs} other (kind, colour) pair(s) in other_kinds and bezel_colours"
                )
        return value

    @field_validator("attribute")
    @classmethod
    def _attribute_name(cls, value: str | None) -> str | None:
        colours = shipped_vocabulary().colour_names
        if value is not None and value not in colours:
            raise ValueError(f"must be one of {', '.join(colours)} or null, got {value!r}")
        return value

    def named_bezel_colours(self) -> tuple[str, ...]:
        """The trim colours the named target is drawn from (see `attribute`)."""
        if self.attribute is None:
            return self.bezel_colours
        vocabulary = shipped_vocabulary()
        named = tuple(c for c in self.bezel_colours if vocabulary.colour_name(c) == self.attribute)
        return named or (vocabulary.colour_hex(self.attribute),)

    @field_validator("size_m")
    @classmethod
    def _plausible_size(cls, value: tuple[float, float]) -> tuple[float, float]:
        return _within(value, 0.05, 1.5)

    @field_validator("height_m")
    @classmethod
    def _above_floor(cls, value: tuple[float, float]) -> tuple[float, float]:
        return _within(value, 0.0, 10.0)

    @field_validator("needle_fraction")
    @classmethod
    def _fraction(cls, value: tuple[float, float]) -> tuple[float, float]:
        return _within(value, 0.0, 1.0)


class WallConfig(StrictModel):
    """The wall the target is mounted on: the plane north = `north_m`, facing south."""

    north_m: float = Field(default=3.0, gt=0.5)
    width_m: float = Field(default=12.0, gt=2.0)
    height_m: float = Field(default=4.0, gt=2.5)
    textures: tuple[WallTexture, ...] = Field(default=("concrete", "brick", "painted_metal"), min_length=1)
    colours: tuple[Colour, ...] = Field(
        default=("#9a9a94", "#a8624a", "#7d8c82", "#b7b2a5", "#5f7386"), min_length=1
    )


class FloorConfig(StrictModel):
    """The floor (z = 0), which the drone takes off from and lands on."""

    textures: tuple[FloorTexture, ...] = Field(default=("concrete", "tiles", "grating"), min_length=1)
    colours: tuple[Colour, ...] = Field(default=("#6e6e6a", "#8a8478", "#55585c"), min_length=1)


class ClutterConfig(StrictModel):
    """Pipes, conduits, junction boxes, brackets and signs, and look-alike distractors."""

    density: Range = (0.3, 0.8)
    """0 = a bare wall, 1 = as many pipes and boxes as fit."""
    distractors: IntRange = (0, 3)
    """How many look-alike objects (other dials, boxes, round signs) to place."""
    distractor_kinds: tuple[DistractorKind, ...] = Field(default=("dial", "box", "sign"), min_length=1)
    keep_out_m: float = Field(default=0.15, ge=0.0)
    """Clear margin around the target that no clutter or distractor enters."""

    @field_validator("density")
    @classmethod
    def _density(cls, value: tuple[float, float]) -> tuple[float, float]:
        return _within(value, 0.0, 1.0)

    @field_validator("distractors")
    @classmethod
    def _count(cls, value: tuple[int, int]) -> tuple[int, int]:
        return _within(value, 0, 10)


class LightingConfig(StrictModel):
    """TinyRenderer's single light: direction, colour and the Phong coefficients."""

    azimuth_deg: Range = (135.0, 225.0)
    """Compass bearing the light comes from (180 = from the south, behind the drone)."""
    elevation_deg: Range = (20.0, 70.0)
    intensity: Range = (0.85, 1.0)
    """Light colour as a grey level in [0, 1]."""
    ambient: Range = (0.45, 0.7)
    diffuse: Range = (0.4, 0.7)
    specular: Range = (0.0, 0.2)
    shadow: bool = False
    """Cast shadows (TinyRenderer renders noticeably slower with them)."""

    @field_validator("intensity", "ambient", "diffuse", "specular")
    @classmethod
    def _unit_interval(cls, value: tuple[float, float]) -> tuple[float, float]:
        return _within(value, 0.0, 1.0)

    @field_validator("elevation_deg")
    @classmethod
    def _above_horizon(cls, value: tuple[float, float]) -> tuple[float, float]:
        return _within(value, 0.0, 90.0)


class SceneConfig(StrictModel):
    """Everything `Scene.build` randomises, as ranges; a seed picks one scene."""

    kinds: dict[str, dict[str, Any]] = Field(default_factory=dict)
    """Target kinds this scene adds to the shipped ones (`drone_inspect_core.vocabulary.parse_kind`):
    `{flange: {image: flange.png, size_m: [0.3, 0.3], words: [flange, pipe flange]}}`; an image's
    path is relative to the scene file. First, so that `target` can name them."""
    target: TargetConfig = TargetConfig()
    wall: WallConfig = WallConfig()
    floor: FloorConfig = FloorConfig()
    clutter: ClutterConfig = ClutterConfig()
    lighting: LightingConfig = LightingConfig()
    camera_noise_std: Range = (0.0, 3.0)
    """Std of the Gaussian pixel noise added to rendered images, in 8-bit grey levels."""

    @field_validator("camera_noise_std")
    @classmethod
    def _noise(cls, value: tuple[float, float]) -> tuple[float, float]:
        return _within(value, 0.0, 64.0)

    @field_validator("kinds", mode="before")
    @classmethod
    def _parse_kinds(cls, value: object, info: ValidationInfo) -> object:
        """Each kind checked (its image readable, its words free); stored as plain data, paths absolute."""
        return validated_kinds(value, (info.context or {}).get("base_dir"))

    @model_validator(mode="after")
    def _known_kinds(self) -> SceneConfig:
        known = self.vocabulary.kind_names
        for field in ("kinds", "other_kinds"):
            for index, name in enumerate(getattr(self.target, field)):
                if name not in known:
                    raise ValueError(
                        f"target.{field}[{index}]: unknown target kind {name!r}; "
                        f"known kinds: {', '.join(known)} (add one under `kinds:`)"
                    )
        return self

    @property
    def vocabulary(self) -> Vocabulary:
        """The shipped vocabulary with this scene's own kinds."""
        return vocabulary_with(self.kinds)


DEFAULT_SCENE = SceneConfig()
"""The default family of scenes (the same as `scenes/default.yaml`)."""


def parse_scene_config(
    data: object, source: str | Path = "<scene config>", base_dir: Path | None = None
) -> SceneConfig:
    """Validate an already-parsed mapping (empty means the defaults); errors name `source` and the field.

    `base_dir`: where a kind's image path is relative to (default: the folder of `source` if it is a file).
    """
    if base_dir is None and isinstance(source, Path):
        base_dir = source.parent
    context = {"base_dir": base_dir}
    return validate_mapping(
        SceneConfig, {} if data is None else data, source, SceneConfigError, context=context
    )


def with_targets(
    config: SceneConfig,
    count: tuple[int, int] | None = None,
    twins: bool | None = None,
    attribute: str | None = None,
    source: str = "<command line>",
) -> SceneConfig:
    """`config` with `target.count`, `.twins` and/or `.attribute` replaced (None: kept), validated as a
    file would be; errors name `source`."""
    data = config.model_dump(mode="json")
    if count is not None:
        data["target"]["count"] = list(count)
    if twins is not None:
        data["target"]["twins"] = twins
    if attribute is not None:
        data["target"]["attribute"] = attribute
    return parse_scene_config(data, source)


def load_scene_config(path: str | Path) -> SceneConfig:
    """Read and validate a scene YAML file.

    Raises `SceneConfigError` naming the file (and the field, where one is at fault) for a
    missing or unreadable file, a YAML syntax error, or a value that fails validation.
    """
    data = read_yaml(path, SceneConfigError)
    return parse_scene_config(data, Path(path))
