"""What a mission benchmark flies: its configuration and its missions, the same for every planner.

Mission i of a benchmark with seed S flies scene seed `scene_seed(S, i)` (31-bit,
drawn from `SeedSequence([S, i])`; the training scenes are drawn the same way from
the dataset seed, so the chance of meeting one is ~1e-5, and seeds a checkpoint
lists as seen in training are skipped), a random target kind, and a random start
with the target anywhere in `view_fraction` of the half view, at a random
distance and yaw.

Several targets (`targets` N > 1, `twins`): every scene holds N targets; the instruction
names the named one with a phrase of the latent planner's `instructions` corpus
(held-out by default: words its training never paired), its trim colour included where
the kind alone would not say which; or, `instructions` an operator-words file
(`controller.evaluation.operator_words`: its templates, words and colour forms), in the operator's
own words, which the loop must understand as it flies (a refused or misread instruction fails).
`absent` (a fraction): those missions' instructions name a target the scene does not hold (a kind
not on the wall, else a colour no target of that kind has) and expect `target_not_found`. One
target, no phrases, nothing absent: today's missions exactly ("center the <kind>", resolved by the kit).

Several instructions per flight (`instructions_per_flight` N > 1, with `targets` >= N): each flight
names N of its scene's targets in turn, the named one first, then the others in the scene's order, each
with a phrase of the corpus (its colour where its kind repeats on the wall); the flight takes off once
and must centre each (per truth, on that instruction's own target). The start is where the operator
would put the drone for such a sequence: in front of the targets, far enough from the wall that all N
of them are within `SEQUENCE_VIEW` of the half view (the distance drawn from `distance_m`, raised where
needed; a scene whose targets need more than `SEQUENCE_MAX_DISTANCE_M` is skipped), the group's middle
at the image centre give or take the slack left, heading square to the wall.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from controller.evaluation.operator_words import OperatorWords, is_operator_words_file, load_operator_words
from controller.missions.schema import Mission, MissionFileError, parse_mission
from controller.missions.vehicles import SIMULATED_VEHICLES
from controller.planning.grounding import TargetQuery
from controller.planning.planners import PLANNER_NAMES
from controller.training.instructions import builtin_templates
from controller.training.phrasing import describe
from drone_inspect_core.vocabulary import Vocabulary, colour_name

SEQUENCE_VIEW = 0.75
"""A sequence flight's start has every target within this fraction of the half view (width and height)."""
SEQUENCE_MAX_DISTANCE_M = 3.2
"""The farthest start of a sequence flight: a scene whose targets need more is skipped."""
ABSENT_TAG = "absent"
"""The tag of a benchmark mission whose instruction names a target the scene does not hold."""
REFUSED_TAG = "refused"
"""The tag of a benchmark mission whose instruction (an operator-words file's) the loop refuses before
take-off; it is not flown, counts as failed, and its `description` says why."""
CORPORA = ("train", "heldout")


BASE_MISSION: dict[str, Any] = {"name": "benchmark", "tags": ["benchmark"]}
"""The base mission of a benchmark given no other: today's in-process missions."""


@dataclass(frozen=True)
class BenchmarkConfig:
    """A benchmark: a base mission that every mission copies (vehicle, planner checkpoint, detector, ε,
    step budget, loop settings, targets, twins, kinds, scene family, faults, speeds, PX4), and what is
    drawn per mission (the scene seed, the random start within these ranges, the instruction's phrase,
    absent targets), for each planner. Build one with `BenchmarkConfig.of(mission_fields, ...)`."""

    base: Mission = field(default_factory=lambda: parse_mission(BASE_MISSION))
    n: int = 200
    seed: int = 0
    planners: tuple[str, ...] = PLANNER_NAMES
    view_fraction: tuple[float, float] = (0.1, 0.85)
    distance_m: tuple[float, float] = (1.5, 3.0)
    yaw_deg: tuple[float, float] = (-10.0, 10.0)
    scene_seed: int | None = None
    """Fly every mission in this one scene of the family (a site: the one a collection was flown in), from
    starts drawn per mission; None: a scene seed of its own per mission (unseen scenes)."""
    instructions: str | None = None
    """The corpus ("train" / "heldout") of the phrases naming the target, or an operator-words file
    (.yaml); None: "heldout" with several targets, twins or absent missions, else today's "center the
    <kind>"."""
    absent: float = 0.0
    """The fraction of missions whose instruction names a target the scene does not hold."""
    instructions_per_flight: int = 1
    """Instructions per flight: N > 1 names N of the scene's targets in turn (see the module docstring)."""
    parallel: int = 1
    ray: str | None = None
    """Run the missions on Ray: "local" (a private local Ray of `parallel` CPUs) or a cluster's address."""
    rerun: bool = False
    """Record each mission as `mission.rrd` in its report folder (needs a report folder to keep)."""
    warm: bool = True
    """Keep a simulated MAVLink vehicle warm between missions, reset for each (False: a fresh one each)."""

    @classmethod
    def of(cls, mission: dict[str, Any] | None = None, **sampling: Any) -> BenchmarkConfig:
        """A benchmark whose base mission is the default one with `mission`'s fields (validated as a
        mission file is: a bad value is named)."""
        base = parse_mission({**BASE_MISSION, **(mission or {})}, "the benchmark's base mission")
        return cls(base=base, **sampling)

    def with_base(self, **fields: Any) -> BenchmarkConfig:
        """The same benchmark over a base mission with `fields` changed (validated)."""
        data = {**self.base.model_dump(mode="json", exclude_unset=True), **fields}
        return replace(self, base=parse_mission(data, "the benchmark's base mission"))

    def __post_init__(self) -> None:
        if self.n < 1 or self.parallel < 1:
            raise ValueError("n and parallel must be >= 1")
        if self.base.vehicle not in SIMULATED_VEHICLES:
            raise ValueError(
                f"vehicle must be one of {', '.join(SIMULATED_VEHICLES)}, got {self.base.vehicle!r}"
            )
        unknown = set(self.planners) - set(PLANNER_NAMES)
        if unknown or not self.planners:
            raise ValueError(f"planners must be among {', '.join(PLANNER_NAMES)}; got {self.planners}")
        if self.instructions is not None and self.instructions not in CORPORA:
            if not is_operator_words_file(self.instructions):
                raise ValueError(
                    f"instructions must be one of {CORPORA} or an operator-words file (.yaml), "
                    f"got {self.instructions!r}"
                )
            _operator_words(self.instructions).check_covers(self.base.vocabulary.kind_names)
        if not 0.0 <= self.absent <= 1.0:
            raise ValueError(f"absent must be a fraction in [0, 1], got {self.absent:g}")
        if self.instructions_per_flight < 1:
            raise ValueError(f"instructions per flight must be >= 1, got {self.instructions_per_flight}")
        if self.instructions_per_flight > self.base.targets:
            raise ValueError(
                f"{self.instructions_per_flight} instructions per flight need as many targets per scene "
                f"(--targets {self.instructions_per_flight}), got {self.base.targets}"
            )
        if self.instructions_per_flight > 1 and self.absent > 0:
            raise ValueError("absent targets go with one instruction per flight")
        if self.scene_seed is not None and self.scene_seed < 0:
            raise ValueError(f"scene_seed must be >= 0, got {self.scene_seed}")
        for name, (lo, hi) in (("view_fraction", self.view_fraction), ("distance_m", self.distance_m),
                               ("yaw_deg", self.yaw_deg)):  # fmt: skip
            if not lo <= hi:
                raise ValueError(f"{name}: the range [{lo:g}, {hi:g}] is empty")

    @property
    def corpus(self) -> str | None:
        """The phrases' corpus, None for today's resolved instruction (see `instructions`)."""
        if self.instructions is not None:
            return self.instructions
        return "heldout" if self.base.targets > 1 or self.base.twins or self.absent > 0 else None

    def as_json(self) -> dict[str, Any]:
        """The configuration as JSON (the base mission as a mission file would hold it)."""
        data = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "base"}
        return {"base": self.base.model_dump(mode="json", exclude_unset=True), **data}


def scene_seed(seed: int, index: int) -> int:
    return int(np.random.SeedSequence([seed, index, 0xBE7C]).generate_state(1)[0] >> 1)


def _draw(seed: int, stream: int) -> np.random.Generator:
    """A stream of its own per scene seed: phrases (1) and absent choices (2) never shift the scenes."""
    return np.random.default_rng([seed, stream, 0x1257])


def benchmark_missions(config: BenchmarkConfig, planner: str, skip_seeds: frozenset[int]) -> list[Mission]:
    """The `n` missions for one planner (the same scenes, starts and instructions for every planner).

    A scene seed whose targets do not fit on the wall (several targets) is skipped like a seen one."""
    from sim_world.scene.sampling_targets import SceneLayoutError

    missions: list[Mission] = []
    index = 0
    while len(missions) < config.n:
        seed = scene_seed(config.seed, index)
        index += 1
        if seed in skip_seeds:
            continue
        absent = config.absent > 0 and float(_draw(seed, 2).random()) < config.absent
        base = config.base
        faults = base.faults.model_dump(mode="json", exclude_unset=True)
        data: dict[str, Any] = {
            **base.model_dump(mode="json", exclude_unset=True),
            "name": f"bench-{config.seed}-{len(missions):04d}-{planner}",
            "tags": [*base.tags, ABSENT_TAG] if absent else list(base.tags),
            "scene": {**base.scene.model_dump(mode="json"), "seed": seed if config.scene_seed is None
                      else config.scene_seed},
            "start": {"random": {
                "seed": seed, "view_fraction": list(config.view_fraction),
                "distance_m": list(config.distance_m), "yaw_deg": list(config.yaw_deg),
            }},
            "planner": planner,
            "expect": {"outcome": "target_not_found"} if absent
            else {"outcome": "centred", "max_steps": base.max_steps},
            **({"faults": {**faults, "seed": seed}} if base.faults.any else {}),
        }  # fmt: skip
        mission = parse_mission(data)
        if config.instructions_per_flight > 1:
            try:
                sequence = sequence_for(mission, config)
            except SceneLayoutError:
                continue
            if sequence is None:  # the targets do not fit in one view from the farthest start
                continue
            mission = _with_words(data, sequence, config)
        elif config.corpus is not None:
            try:
                mission = _with_words(
                    data, {"instruction": instruction_for(mission, config.corpus, absent)}, config
                )
            except SceneLayoutError:
                continue
        missions.append(mission)
    return missions


def _with_words(data: dict[str, Any], words: dict[str, Any], config: BenchmarkConfig) -> Mission:
    """The mission with its drawn instruction(s); one the loop refuses (an operator's words it does not
    understand, or twins named without a colour) is the mission without them, tagged `REFUSED_TAG`: the
    phrases of the planner's own corpora are always understood, so a refusal of those is a bug and raises."""
    try:
        return parse_mission({**data, **words})
    except MissionFileError as exc:
        if config.corpus in CORPORA:
            raise
        return parse_mission(
            {**data, "tags": [*data["tags"], REFUSED_TAG], "description": f"refused before take-off: {exc}"}
        )


def sequence_for(mission: Mission, config: BenchmarkConfig) -> dict[str, Any] | None:
    """A sequence flight's `instructions` and `start` for `mission`'s scene (see the module docstring);
    None when its targets do not fit in one view. Raises `SceneLayoutError` when they do not fit on the
    wall."""
    from controller.missions.setup import scene_config_for  # the simulator's scene code: only when drawn
    from sim_world.rendering.camera import CameraConfig
    from sim_world.scene.sampling import sample_scene

    seed = mission.scene.seed
    scene = sample_scene(scene_config_for(mission), seed)
    targets = scene.targets[: config.instructions_per_flight]
    kinds = [t.kind for t in scene.targets]
    corpus = config.corpus or "heldout"
    words, rng = _draw(seed, 1), _draw(seed, 3)
    phrases = []
    for target in targets:
        repeats = mission.twins or kinds.count(target.kind) > 1
        name = TargetQuery(target.kind, colour_name(target.bezel_colour) if repeats else None)
        phrases.append(phrase(name, corpus, words))
    east = [t.east_m for t in targets]
    up = [t.height_m for t in targets]
    middle_east, middle_up = (max(east) + min(east)) / 2, (max(up) + min(up)) / 2
    half_e, half_u = (max(east) - min(east)) / 2, (max(up) - min(up)) / 2
    tan_half = math.tan(math.radians(CameraConfig().hfov_deg) / 2)  # a square image: the same vertically
    need_m = max(half_e, half_u) / (SEQUENCE_VIEW * tan_half)
    distance_m = max(float(rng.uniform(*config.distance_m)), need_m)
    if distance_m > SEQUENCE_MAX_DISTANCE_M:
        return None
    slack_e = max(0.0, SEQUENCE_VIEW * tan_half * distance_m - half_e)  # how far the group may sit off centre
    slack_u = max(0.0, SEQUENCE_VIEW * tan_half * distance_m - half_u)
    named = targets[0]
    start = {
        "right_m": middle_east - named.east_m + float(rng.uniform(-slack_e, slack_e)),
        "up_m": middle_up - named.height_m + float(rng.uniform(-slack_u, slack_u)),
        "distance_m": distance_m,
        "yaw_deg": 0.0,
    }
    return {"instructions": phrases, "start": start}


def instruction_for(mission: Mission, corpus: str, absent: bool) -> str:
    """A phrase of `corpus` naming the mission's named target (its colour where the kind alone would not
    say which) or, `absent`, a target its scene does not hold; drawn from the scene seed's own stream.
    Raises `SceneLayoutError` when the scene's targets do not fit on its wall."""
    from controller.missions.setup import scene_config_for  # the simulator's scene code: only when drawn
    from sim_world.scene.sampling import sample_scene

    seed = mission.scene.seed
    scene = sample_scene(scene_config_for(mission), seed)
    targets = [(t.kind, colour_name(t.bezel_colour)) for t in scene.targets]
    if absent:
        name = _absent_name(targets, _draw(seed, 2), with_colour=mission.twins, vocabulary=mission.vocabulary)
    else:
        kind, attribute = targets[0]
        repeats = mission.twins or any(k == kind for k, _ in targets[1:])
        name = TargetQuery(kind, attribute if repeats else None)
    return phrase(name, corpus, _draw(seed, 1))


def phrase(name: TargetQuery, corpus: str, rng: np.random.Generator) -> str:
    """An instruction naming `name`: a phrase of the corpus ("train" / "heldout"), or of an
    operator-words file (`corpus` its path)."""
    if corpus in CORPORA:
        return describe(name, builtin_templates(corpus), corpus, rng)
    return _operator_words(corpus).instruction(name, rng)


def _operator_words(path: str) -> OperatorWords:
    """An operator-words file, read once per version of it rather than once per mission."""
    try:
        stat = Path(path).stat()
        version: tuple[int, int] | None = (stat.st_mtime_ns, stat.st_size)
    except OSError:
        version = None  # load_operator_words names the file and why it cannot be read
    return _read_operator_words(path, version)


@functools.lru_cache(maxsize=8)
def _read_operator_words(path: str, version: tuple[int, int] | None) -> OperatorWords:
    return load_operator_words(path)


def _absent_name(
    targets: list[tuple[str, str]], rng: np.random.Generator, with_colour: bool, vocabulary: Vocabulary
) -> TargetQuery:
    """A kind no target has (by kind alone; with a colour too where `with_colour`: a twins mission's
    instruction always names one), else a kind with a colour no target of it has."""
    rng.random()  # the draw that chose "absent"
    kinds = {kind for kind, _ in targets}
    missing = [k for k in vocabulary.kind_names if k not in kinds]
    if missing:
        kind = missing[int(rng.integers(len(missing)))]
        colours = vocabulary.colour_names
        return TargetQuery(kind, colours[int(rng.integers(len(colours)))] if with_colour else None)
    kinds_known = vocabulary.kind_names
    kind = kinds_known[int(rng.integers(len(kinds_known)))]
    free = [c for c in vocabulary.colour_names if (kind, c) not in targets]
    return TargetQuery(kind, free[int(rng.integers(len(free)))])
