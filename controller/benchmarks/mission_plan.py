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
the kind alone would not say which. `absent` (a fraction): those missions' instructions
name a target the scene does not hold (a kind not on the wall, else a colour no target of
that kind has) and expect `target_not_found`. One target, no phrases, nothing absent:
today's missions exactly ("center the <kind>", resolved by the kit).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from controller.missions.schema import (
    ARDUPILOT_SITL,
    PX4_SITL,
    SIM,
    SIM_MAVLINK,
    Mission,
    PortSpec,
    parse_mission,
)
from controller.missions.suite import UDP_PORTS_PER_MISSION
from controller.training.instructions import builtin_templates
from controller.training.phrasing import TargetName, describe
from drone_inspect_core.targets import ATTRIBUTE_COLOURS, TARGET_KINDS, colour_name

ABSENT_TAG = "absent"
"""The tag of a benchmark mission whose instruction names a target the scene does not hold."""
CORPORA = ("train", "heldout")


@dataclass(frozen=True)
class BenchmarkConfig:
    """What to fly. `vehicle`: `sim` (in-process), `sim-mavlink` (sim-vehicle + MAVSDK + MJPEG),
    `px4-sitl` (real PX4 SITL flying the world, lockstep, `px4_speed` "max" by default) or
    `ardupilot-sitl` (real ArduCopter SITL, likewise, `ardupilot_speed`)."""

    n: int = 200
    seed: int = 0
    planners: tuple[str, ...] = ("latent", "classic", "random", "oracle")
    vehicle: str = SIM
    max_steps: int = 20
    epsilon_px: float | None = None
    view_fraction: tuple[float, float] = (0.1, 0.85)
    distance_m: tuple[float, float] = (1.5, 3.0)
    yaw_deg: tuple[float, float] = (-10.0, 10.0)
    checkpoint: str | None = None
    detector: str = "image"
    """`image` (what the product uses) or `truth` (in-process only: isolates the planners from detection)."""
    detector_checkpoint: str | None = None
    """The image detector's run folder; None: its shipped weights."""
    scale_moves: bool = True
    """The loop's move scheme: scaled with the detector's offset (default) or the paper's fixed lengths."""
    second_choices: int | None = None
    """The loop's `max_second_choices` (None: its default; 0: a "no move" far from centre is a stall)."""
    targets: int = 1
    """Targets in every scene, the named one included (1..4)."""
    twins: bool = False
    """One other target shares the named target's kind, in another trim colour (needs targets >= 2)."""
    instructions: str | None = None
    """The corpus ("train" / "heldout") of the phrases naming the target; None: "heldout" with several
    targets, twins or absent missions, else today's "center the <kind>"."""
    absent: float = 0.0
    """The fraction of missions whose instruction names a target the scene does not hold."""
    parallel: int = 1
    udp_port_base: int = 15400  # 15400-15479: clear of the tests' fixed ports (146xx-150xx)
    http_port_base: int = 19400
    px4_dir: str | None = None
    """PX4 SITL build folder for `px4-sitl` (None: $PX4_SITL_DIR)."""
    px4_speed: float | str = "max"
    ardupilot_dir: str | None = None
    """ArduCopter SITL folder for `ardupilot-sitl` (None: $ARDUPILOT_SITL_DIR, ../shared/ardupilot-sitl)."""
    ardupilot_speed: float | str = "max"
    sim_speed: float | str = 1.0
    """sim-mavlink: the sim-vehicle's speed, a factor or "max" (the missions' `sim_speed`)."""
    faults: dict[str, Any] | None = None
    """Injected faults, the `faults:` section of a mission file (seeded per mission by its scene seed)."""
    ray: str | None = None
    """Run the missions on Ray: "local" (a private local Ray of `parallel` CPUs) or a cluster's address."""
    rerun: bool = False
    """Record each mission as `mission.rrd` in its report folder (needs a report folder to keep)."""

    def __post_init__(self) -> None:
        if self.n < 1 or self.parallel < 1:
            raise ValueError("n and parallel must be >= 1")
        if self.vehicle not in (SIM, SIM_MAVLINK, PX4_SITL, ARDUPILOT_SITL):
            raise ValueError(
                f"vehicle must be {SIM!r}, {SIM_MAVLINK!r}, {PX4_SITL!r} or {ARDUPILOT_SITL!r}, "
                f"got {self.vehicle!r}"
            )
        unknown = set(self.planners) - {"latent", "classic", "random", "oracle"}
        if unknown or not self.planners:
            raise ValueError(f"planners must be among latent, classic, random, oracle; got {self.planners}")
        if not 1 <= self.targets <= 4:
            raise ValueError(f"targets must be 1..4, got {self.targets}")
        if self.twins and self.targets < 2:
            raise ValueError("twins need targets >= 2 (the named one and its twin)")
        if self.instructions is not None and self.instructions not in CORPORA:
            raise ValueError(f"instructions must be one of {CORPORA}, got {self.instructions!r}")
        if self.sim_speed != 1.0 and self.vehicle != SIM_MAVLINK:
            raise ValueError(f"sim_speed goes with vehicle {SIM_MAVLINK!r} (SITL: px4/ardupilot_speed)")
        if not 0.0 <= self.absent <= 1.0:
            raise ValueError(f"absent must be a fraction in [0, 1], got {self.absent:g}")

    @property
    def corpus(self) -> str | None:
        """The phrases' corpus, None for today's resolved instruction (see `instructions`)."""
        if self.instructions is not None:
            return self.instructions
        return "heldout" if self.targets > 1 or self.twins or self.absent > 0 else None


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
        slot = len(missions) % 20
        absent = config.absent > 0 and float(_draw(seed, 2).random()) < config.absent
        data: dict[str, Any] = {
            "name": f"bench-{config.seed}-{len(missions):04d}-{planner}",
            "tags": ["benchmark", ABSENT_TAG] if absent else ["benchmark"],
            "scene": {"seed": seed},
            **({"targets": config.targets} if config.targets != 1 else {}),
            **({"twins": True} if config.twins else {}),
            "start": {"random": {
                "seed": seed, "view_fraction": list(config.view_fraction),
                "distance_m": list(config.distance_m), "yaw_deg": list(config.yaw_deg),
            }},
            "vehicle": config.vehicle,
            "planner": planner,
            "checkpoint": config.checkpoint,
            "detector": config.detector,
            "epsilon_px": config.epsilon_px,
            "max_steps": config.max_steps,
            "loop": {"scale_moves": config.scale_moves}
            | ({} if config.second_choices is None else {"max_second_choices": config.second_choices}),
            "expect": {"outcome": "target_not_found"} if absent
            else {"outcome": "centred", "max_steps": config.max_steps},
            "ports": PortSpec(
                mavlink_udp=config.udp_port_base + UDP_PORTS_PER_MISSION * slot,
                http=config.http_port_base + slot,
            ).model_dump(),
            **({"sim_speed": config.sim_speed} if config.vehicle == SIM_MAVLINK else {}),
            **({"px4": {"dir": config.px4_dir, "speed": config.px4_speed, "keep_ulog": False}}
               if config.vehicle == PX4_SITL else {}),
            **({"ardupilot": {"dir": config.ardupilot_dir, "speed": config.ardupilot_speed,
                              "keep_logs": False}} if config.vehicle == ARDUPILOT_SITL else {}),
            **({"faults": {**config.faults, "seed": seed}} if config.faults else {}),
        }  # fmt: skip
        mission = parse_mission(data)
        if config.corpus is not None:
            try:
                mission = parse_mission(
                    {**data, "instruction": instruction_for(mission, config.corpus, absent)}
                )
            except SceneLayoutError:
                continue
        missions.append(mission)
    return missions


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
        name = _absent_name(targets, _draw(seed, 2), with_colour=mission.twins)
    else:
        kind, attribute = targets[0]
        repeats = mission.twins or any(k == kind for k, _ in targets[1:])
        name = TargetName(kind, attribute if repeats else None)
    return describe(name, builtin_templates(corpus), corpus, _draw(seed, 1))


def _absent_name(targets: list[tuple[str, str]], rng: np.random.Generator, with_colour: bool) -> TargetName:
    """A kind no target has (by kind alone; with a colour too where `with_colour`: a twins mission's
    instruction always names one), else a kind with a colour no target of it has."""
    rng.random()  # the draw that chose "absent"
    kinds = {kind for kind, _ in targets}
    missing = [k for k in TARGET_KINDS if k not in kinds]
    if missing:
        kind = missing[int(rng.integers(len(missing)))]
        colours = tuple(ATTRIBUTE_COLOURS)
        return TargetName(kind, colours[int(rng.integers(len(colours)))] if with_colour else None)
    kind = TARGET_KINDS[int(rng.integers(len(TARGET_KINDS)))]
    free = [c for c in ATTRIBUTE_COLOURS if (kind, c) not in targets]
    return TargetName(kind, free[int(rng.integers(len(free)))])
