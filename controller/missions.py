"""Missions: finding mission files, judging a flown mission against its expectations, the result row.

The file format is `controller.mission_schema`; flying one is
`controller.mission_runner`. A mission passes when the loop's outcome is the
expected one and every expectation holds; "centred" is judged by simulator
truth where the mission has it (the detector could be wrong), otherwise by the
detector's final offset.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

from controller.centring_loop import Outcome, StepRecord
from controller.mission_schema import Mission, MissionFileError, RandomStartSpec, StartOffset, load_mission
from flight.link_faults import LinkFaults
from sim_world.scene_config import DEFAULT_SCENE, SceneConfig, load_scene_config, parse_scene_config
from sim_world.wind import WindConfig


@dataclass(frozen=True)
class MissionResult:
    """One flown mission, as a suite table row and a JSON object."""

    name: str
    planner: str
    outcome: str
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
    """Boundary refinement moves the loop flew after the planner chose "no move" (see centring_loop)."""
    info: dict[str, Any] = field(default_factory=dict)
    vehicle_clock_s: dict[str, float] = field(default_factory=dict)
    files: dict[str, str | None] = field(default_factory=dict)
    truth_extremes: dict[str, Any] | None = None
    """Simulated MAVLink vehicles: the largest speeds and excursions from home per simulator truth."""
    """What the report folder holds: report, trajectory, gif, tlog (None: not written)."""
    """Milestones (connected, ready, offboard) on the vehicle's clock (PX4 SITL: its simulated time)."""

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
    return sum(1 for s in steps if s.action is not None or s.event == "recovery")


def judge(
    mission: Mission,
    outcome: Outcome,
    steps: int,
    epsilon_px: float,
    final_truth_offset_px: tuple[float, float] | None,
    final_detector_offset_px: tuple[float, float] | None,
    has_truth: bool,
) -> list[str]:
    """Every expectation of `mission` that the flight broke, in words; empty when it passed."""
    expect = mission.expect
    failures: list[str] = []
    if outcome.value != expect.outcome:
        failures.append(f"outcome {outcome.value}, expected {expect.outcome}")
    final = final_truth_offset_px if has_truth else final_detector_offset_px
    source = "truth" if has_truth else "detector"
    error_px = None if final is None else max(abs(final[0]), abs(final[1]))
    if expect.outcome == Outcome.CENTRED.value:
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


def find_mission_files(directory: str | Path) -> list[Path]:
    """The mission files (`*.yaml`, `*.yml`) of a suite folder, sorted; errors name the folder."""
    directory = Path(directory)
    if not directory.is_dir():
        raise MissionFileError(directory, None, "not a folder of mission files")
    files = sorted(p for p in directory.iterdir() if p.suffix in (".yaml", ".yml") and p.is_file())
    if not files:
        raise MissionFileError(directory, None, "no mission files (*.yaml) in this folder")
    return files


def load_suite(directory: str | Path, overrides: dict[str, Any] | None = None) -> list[tuple[Path, Mission]]:
    """Load and validate every mission of a folder before flying any (a bad file fails the suite early)."""
    missions = [(path, load_mission(path, overrides)) for path in find_mission_files(directory)]
    names = [m.name for _, m in missions]
    duplicates = sorted({n for n in names if names.count(n) > 1})
    if duplicates:
        raise MissionFileError(directory, "name", f"mission names must be unique, repeated: {duplicates}")
    return missions


def scene_config_for(mission: Mission) -> SceneConfig:
    """The mission's scene family (file, inline or default), restricted to its target kind."""
    spec = mission.scene.config
    if spec is None:
        config = DEFAULT_SCENE
    elif isinstance(spec, str):
        config = load_scene_config(spec)
    else:
        config = parse_scene_config(spec, source=f"mission {mission.name}: scene.config")
    if mission.target_kind is not None:
        target = config.target.model_copy(update={"kinds": (mission.target_kind,)})
        config = config.model_copy(update={"target": target})
    return config


def wind_config_for(mission: Mission) -> WindConfig:
    """The mission's wind for a simulated world (calm when it names none); `faults.gust_m_s`: the gusts."""
    wind = WindConfig()
    if mission.wind is not None:
        wind = WindConfig(
            mean_enu_m_s=mission.wind.mean_enu_m_s,
            gust_std_m_s=mission.wind.gust_std_m_s,
            gust_time_constant_s=mission.wind.gust_time_constant_s,
        )
    if mission.faults.gust_m_s:
        wind = replace(wind, gust_std_m_s=mission.faults.gust_m_s)
    return wind


def link_faults_for(mission: Mission) -> LinkFaults | None:
    spec = mission.faults.link
    return None if spec is None else LinkFaults(**spec.model_dump(), seed=mission.faults.seed)


def start_offset_for(mission: Mission, hfov_deg: float, vfov_deg: float) -> StartOffset:
    """The fixed start, or the seeded random draw for this camera."""
    if isinstance(mission.start, RandomStartSpec):
        return mission.start.random.draw(hfov_deg, vfov_deg)
    return mission.start
