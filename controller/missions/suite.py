"""A mission suite: every mission of a folder, flown (in parallel if asked), as a table and JUnit XML.

All mission files are validated before the first flight, so a typo fails the
suite at once. Each mission writes its report folder under `report_dir/<name>/`.
Missions that fly through `sim-vehicle` get their own UDP and HTTP ports from the
suite's port ranges (one slot per mission), so parallel ones never collide.
A mission that cannot even start (bad URL, missing checkpoint) is a failed row,
not a crashed suite.
"""

from __future__ import annotations

import io
import logging
import time
import xml.etree.ElementTree as ET
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from multiprocessing import get_context
from pathlib import Path
from typing import Any

from controller.missions.kits.base import LoadedModels, shared_models
from controller.missions.report import claim_report_dir
from controller.missions.results import MissionResult
from controller.missions.schema import (
    ARDUPILOT_SITL,
    PX4_SITL,
    Mission,
    MissionFileError,
    load_mission,
)
from controller.planning.loop_records import Outcome
from drone_inspect_core.files import release_claim, write_atomic

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SuiteOptions:
    """How to run a suite (simulated vehicles take free ports per mission: any number run at once)."""

    report_dir: Path
    parallel: int = 1
    overrides: dict[str, Any] | None = None
    tags: tuple[str, ...] = ()
    """Fly only missions with at least one of these tags (empty: all)."""
    exclude_tags: tuple[str, ...] = ()
    px4_dir: str | None = None
    """The PX4 SITL folder for `px4-sitl` missions that name none (None: $PX4_SITL_DIR)."""
    ardupilot_dir: str | None = None
    """The ArduPilot SITL folder for `ardupilot-sitl` missions that name none (None: their default)."""

    def __post_init__(self) -> None:
        if self.parallel < 1:
            raise ValueError(f"parallel must be >= 1, got {self.parallel}")


@dataclass(frozen=True)
class SuiteResult:
    results: list[MissionResult]
    wall_s: float

    @property
    def passed(self) -> bool:
        return bool(self.results) and all(r.passed for r in self.results)

    @property
    def failed(self) -> list[MissionResult]:
        return [r for r in self.results if not r.passed]


_WORKER_MODELS: dict[str, LoadedModels] = {}
"""A worker process's models, loaded once by `_init_worker` (the pool's initializer)."""


def _init_worker(missions: list[Mission], threads: int) -> None:
    import torch

    torch.set_num_threads(threads)
    _WORKER_MODELS["models"] = shared_models(missions)


def _fly_one(mission: Mission, out_dir: Path, models: LoadedModels | None = None) -> MissionResult:
    """One mission in a worker (or in this process), with the models its process shares; never raises
    for a mission that fails."""
    from controller.missions.runner import run_mission

    start = time.perf_counter()
    try:
        return run_mission(mission, out_dir, models=models or _WORKER_MODELS.get("models"))
    except Exception as exc:  # could not start: a failed row with the reason
        log.error("mission %s could not fly: %s", mission.name, exc)
        return failed_to_start(mission, f"{type(exc).__name__}: {exc}", time.perf_counter() - start)


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


def failed_to_start(mission: Mission, error: str, wall_s: float) -> MissionResult:
    return MissionResult(
        name=mission.name,
        planner=mission.planner,
        outcome=Outcome.ERROR,
        passed=False,
        failures=(f"error: {error}",),
        steps=0,
        moves=0,
        epsilon_px=mission.epsilon_px or 0.0,
        final_truth_offset_px=None,
        final_detector_offset_px=None,
        wall_s=wall_s,
        vehicle_s=0.0,
        overhead_ms_mean=None,
        error=error,
        tags=mission.tags,
    )


def with_sitl_dirs(missions: list[Mission], options: SuiteOptions) -> list[Mission]:
    """SITL missions (px4-sitl, ardupilot-sitl) that name no autopilot folder get the suite's."""
    out = []
    for mission in missions:
        if mission.vehicle == PX4_SITL and mission.px4.dir is None and options.px4_dir is not None:
            mission = mission.model_copy(
                update={"px4": mission.px4.model_copy(update={"dir": options.px4_dir})}
            )
        if mission.vehicle == ARDUPILOT_SITL and mission.ardupilot.dir is None and options.ardupilot_dir:
            spec = mission.ardupilot.model_copy(update={"dir": options.ardupilot_dir})
            mission = mission.model_copy(update={"ardupilot": spec})
        out.append(mission)
    return out


def _selected(mission: Mission, options: SuiteOptions) -> bool:
    tags = set(mission.tags)
    return (not options.tags or bool(tags & set(options.tags))) and not tags & set(options.exclude_tags)


def run_suite(directory: str | Path, options: SuiteOptions) -> SuiteResult:
    """Validate, then fly every mission of `directory`; results in file order."""
    start = time.perf_counter()
    selected = [path for path, m in load_suite(directory) if _selected(m, options)]
    missions = [load_mission(path, options.overrides) for path in selected]  # overrides on the chosen only
    if not missions:
        raise ValueError(
            f"no mission in {directory} matches tags {options.tags} minus {options.exclude_tags}"
        )
    missions = with_sitl_dirs(missions, options)
    out = claim_report_dir(options.report_dir)  # a suite's reports never go over an earlier run's
    for mission in missions:  # each mission then claims its own (empty) folder
        (out / mission.name).mkdir()
    release_claim(out)
    results: dict[str, MissionResult] = {}
    if options.parallel == 1:
        models = shared_models(missions)  # loaded once, not once a mission
        for mission in missions:
            results[mission.name] = _fly_one(mission, out / mission.name, models)
            _log_row(results[mission.name])
    else:
        context = get_context("spawn")
        with ProcessPoolExecutor(options.parallel, context, _init_worker, (missions, 1)) as pool:
            futures = {pool.submit(_fly_one, m, out / m.name): m for m in missions}
            for future in as_completed(futures):
                result = future.result()
                results[result.name] = result
                _log_row(result)
    return SuiteResult([results[m.name] for m in missions], time.perf_counter() - start)


def _log_row(result: MissionResult) -> None:
    log.info(
        "%s %s: %s in %d steps",
        "PASS" if result.passed else "FAIL",
        result.name,
        result.outcome,
        result.steps,
    )


def format_table(suite: SuiteResult) -> str:
    """A fixed-width table: one row per mission, then a summary line."""
    columns = (
        ("mission", 28, "<"),
        ("planner", 8, "<"),
        ("result", 6, "<"),
        ("outcome", 16, "<"),
        ("steps", 5, ">"),
    )
    header = (
        " ".join(f"{name:{align}{width}}" for name, width, align in columns)
        + f" {'refine':>6} {'offset px':>9} {'wall s':>7}"
    )
    lines = [header, "-" * len(header)]
    for r in suite.results:
        error = r.final_truth_error_px
        offset = "-" if error is None else f"{error:.1f}"
        lines.append(
            f"{r.name[:28]:<28} {r.planner:<8} {'PASS' if r.passed else 'FAIL':<6} {r.outcome:<16} "
            f"{r.steps:>5} {r.refinement_moves:>6} {offset:>9} {r.wall_s:>7.1f}"
        )
        lines += [f"    - {failure}" for failure in r.failures]
    passed = sum(r.passed for r in suite.results)
    lines.append(f"{passed}/{len(suite.results)} passed in {suite.wall_s:.1f} s")
    return "\n".join(lines)


def write_junit(suite: SuiteResult, path: str | Path, name: str = "missions") -> None:
    """JUnit XML (one testcase per mission) for CI systems."""
    failures = len(suite.failed)
    root = ET.Element(
        "testsuite", name=name, tests=str(len(suite.results)), failures=str(failures), errors="0",
        time=f"{suite.wall_s:.3f}",
    )  # fmt: skip
    for r in suite.results:
        case = ET.SubElement(
            root, "testcase", classname=f"missions.{r.planner}", name=r.name, time=f"{r.wall_s:.3f}"
        )
        if not r.passed:
            failure = ET.SubElement(case, "failure", message="; ".join(r.failures)[:500], type=r.outcome)
            failure.text = "\n".join(r.failures)
        out = ET.SubElement(case, "system-out")
        offset = r.final_truth_offset_px
        out.text = (
            f"outcome={r.outcome} steps={r.steps} refinement_moves={r.refinement_moves} "
            f"final_offset_px={offset} report={r.report_dir}"
        )
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    buffer = io.BytesIO()
    ET.ElementTree(root).write(buffer, encoding="utf-8", xml_declaration=True)
    write_atomic(path, buffer.getvalue())
