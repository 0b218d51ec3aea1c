"""Randomised centring missions from unseen scene seeds, planners side by side.

The missions (unseen scenes, random starts, several targets, absent targets) are
`controller.benchmarks.mission_plan`'s; every planner flies the same ones.

Per planner: success rate (centred per truth within ε, within the step budget),
mean steps over its successes, its mean steps over the oracle's on the missions
both solved (a ratio of means), final truth offset (mean, p95, max), the loop's
boundary refinement moves (flown when the planner chose "no move" just outside
the stop threshold: total, and missions that needed one), and the loop's overhead
per step (everything but the move). Several targets: wrong-target centrings (the
loop stopped, but per truth on another target; never a success) in their own
column. Absent-target missions count apart: ended `target_not_found` / flew a move. Where the
planner says whether the target is in view (a calibrated latent checkpoint), the missions in which it
said "not in view" of a detection of the named target, present and absent ones apart.
"""

from __future__ import annotations

import atexit
import json
import logging
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from controller.benchmarks.mission_plan import ABSENT_TAG, REFUSED_TAG, BenchmarkConfig, benchmark_missions
from controller.missions.kits.base import LoadedModels
from controller.missions.report import REPORT_JSON, claim_report_dir, write_setup_failure
from controller.missions.results import MissionResult
from controller.missions.schema import ARDUPILOT_SITL, PX4_SITL, SIM_MAVLINK, Mission, parse_mission
from controller.missions.suite import failed_to_start
from controller.planning.grounding import InstructionRefused
from drone_inspect_core.files import release_claim
from drone_inspect_core.parallel import gather, task_executor
from flight.safety import SafetyLimits

log = logging.getLogger(__name__)


def _load_models(config: BenchmarkConfig) -> LoadedModels:
    """The models every mission of the benchmark shares, and the simulator it keeps warm (a simulated
    MAVLink vehicle, reset for each mission: `controller.missions.kits.warm`) unless told not to."""
    from controller.planning.planners import LatentPlannerAdapter
    from perception.image_detector import ImageDetector

    base = config.base
    latent = LatentPlannerAdapter(base.checkpoint) if "latent" in config.planners else None
    detector = None
    if base.detector == "image":
        path = base.detector_checkpoint
        detector = ImageDetector.shipped() if path is None else ImageDetector.load(path)
    simulators = None
    if config.warm and base.vehicle in WARM_VEHICLES:
        from controller.missions.kits.warm import WarmSimulators

        simulators = WarmSimulators()
    return LoadedModels(
        detector=detector,
        latent=latent,
        latent_checkpoint=base.checkpoint,
        detector_checkpoint=base.detector_checkpoint,
        simulators=simulators,
    )


WARM_VEHICLES = (SIM_MAVLINK, PX4_SITL, ARDUPILOT_SITL)
"""The simulated vehicles a benchmark keeps warm between missions (`BenchmarkConfig.warm`)."""

MISSION_RRD = "mission.rrd"
"""A mission's Rerun recording in its report folder (`rerun=True`)."""

# Each worker process loads the models once (`_init_worker`, the pool's initializer) and keeps them here.
_WORKER_MODELS: dict[str, LoadedModels] = {}


def _init_worker(config: BenchmarkConfig) -> None:
    import torch

    torch.set_num_threads(1)
    models = _WORKER_MODELS["models"] = _load_models(config)
    if models.simulators is not None:  # the worker's warm simulator ends with the worker
        atexit.register(models.simulators.close)


def _fly(
    mission: Mission, out_dir: Path, models: LoadedModels | None = None, rerun: bool = False
) -> MissionResult:
    from controller.missions.runner import run_mission

    if REFUSED_TAG in mission.tags:  # the loop refuses its words before take-off: nothing flies
        write_setup_failure(out_dir, mission, InstructionRefused(mission.description))
        return failed_to_start(mission, mission.description, 0.0)
    models = models or _WORKER_MODELS.get("models")
    start = time.perf_counter()
    rerun_path = out_dir / MISSION_RRD if rerun else None
    try:
        return run_mission(mission, out_dir, media=False, models=models, rerun_path=rerun_path)
    except Exception as exc:
        log.error("benchmark mission %s could not fly: %s", mission.name, exc)
        return failed_to_start(mission, f"{type(exc).__name__}: {exc}", time.perf_counter() - start)


def _as_result(result: MissionResult | BaseException, mission: Mission) -> MissionResult:
    """A task that failed outside the mission (a worker that crashed, a node that left) counts as a
    mission that could not fly, named with the reason; the other missions' results stand."""
    if isinstance(result, MissionResult):
        return result
    return failed_to_start(mission, f"task failed: {type(result).__name__}: {result}", 0.0)


def run_benchmark(
    config: BenchmarkConfig, skip_seeds: frozenset[int] = frozenset(), report_dir: Path | None = None
) -> dict[str, Any]:
    """Fly every planner on the same missions; returns the summary and every mission's row (JSON-able)."""
    with tempfile.TemporaryDirectory(prefix="bench-missions-") as tmp:
        out = claim_report_dir(report_dir) if report_dir is not None else Path(tmp)
        runs = [(m, out / m.name) for p in config.planners for m in benchmark_missions(config, p, skip_seeds)]
        for _, path in runs:  # each mission then claims its own (empty) folder
            path.mkdir()
        release_claim(out)
        started = time.perf_counter()
        with task_executor(config.parallel, config.ray, _init_worker, (config,)) as pool:
            if pool is None:
                models = _load_models(config)
                try:
                    results = [
                        _fly(mission, path, models, config.rerun)
                        for mission, path in tqdm(runs, desc="missions", unit="mission")
                    ]
                finally:
                    if models.simulators is not None:
                        models.simulators.close()
            else:
                futures = [pool.submit(_fly, m, p, None, config.rerun) for m, p in runs]
                with tqdm(total=len(futures), desc="missions", unit="mission") as bar:
                    done = gather(
                        futures, lambda i: f"{runs[i][0].name} (scene seed {runs[i][0].scene.seed})", bar
                    )
                results = [_as_result(r, m) for r, (m, _) in zip(done, runs, strict=True)]
        wall_s = time.perf_counter() - started
        summary = summarise(config, results, wall_s)
        summary["limits"]["reports_incomplete"] = [m.name for m, path in runs if not _report_complete(path)]
    return summary


def _report_complete(folder: Path) -> bool:
    """A report.json that says how the mission ended (finished, or failed to start and why)."""
    try:
        report = json.loads((folder / REPORT_JSON).read_text())
    except (OSError, ValueError):
        return False
    return report.get("status") in ("finished", "failed_to_start") and "outcome" in report


def _by_index(results: list[MissionResult], planner: str) -> dict[str, MissionResult]:
    return {r.name.rsplit("-", 1)[0]: r for r in results if r.planner == planner}


def summarise(config: BenchmarkConfig, results: list[MissionResult], wall_s: float) -> dict[str, Any]:
    oracle = _by_index(results, "oracle")
    planners: dict[str, Any] = {}
    for planner in config.planners:
        every = _by_index(results, planner)
        rows = {key: r for key, r in every.items() if ABSENT_TAG not in r.tags}
        absent = [r for r in every.values() if ABSENT_TAG in r.tags]
        ok = [r for r in rows.values() if r.passed]
        errors = [r.final_truth_error_px for r in rows.values() if r.final_truth_error_px is not None]
        both = [key for key, r in rows.items() if r.passed and key in oracle and oracle[key].passed]
        oracle_steps = sum(oracle[key].steps for key in both)
        overhead = [r.overhead_ms_mean for r in rows.values() if r.overhead_ms_mean is not None]
        planners[planner] = {
            "missions": len(rows),
            "successes": len(ok),
            "success_rate": len(ok) / len(rows) if rows else 0.0,
            "mean_steps": statistics.fmean(r.steps for r in ok) if ok else None,
            "mean_steps_over_oracle": sum(rows[k].steps for k in both) / oracle_steps
            if oracle_steps
            else None,
            "missions_both_solved": len(both),
            "final_offset_px_mean": statistics.fmean(errors) if errors else None,
            "final_offset_px_p95": float(np.percentile(errors, 95)) if errors else None,
            "final_offset_px_max": max(errors) if errors else None,
            "overhead_ms_mean": statistics.fmean(overhead) if overhead else None,
            "refinement_moves": sum(r.refinement_moves for r in rows.values()),
            "missions_with_refinement": sum(r.refinement_moves > 0 for r in rows.values()),
            "second_choice_moves": sum(r.second_choice_moves for r in rows.values()),
            "missions_with_second_choice": sum(r.second_choice_moves > 0 for r in rows.values()),
            "wrong_target": sum(r.wrong_target for r in rows.values()),
            "refused": sum(REFUSED_TAG in r.tags for r in every.values()),
            "not_in_view": {  # the planner said "not in view" of a detection of the named target
                "present_missions": sum(r.not_in_view_reads > 0 for r in rows.values()),
                "absent_missions": sum(r.not_in_view_reads > 0 for r in absent),
                "reads": sum(r.not_in_view_reads for r in every.values()),
            },
            "absent": {
                "missions": len(absent),
                "not_found": sum(r.outcome == "target_not_found" for r in absent),
                "wandered": sum(r.moves > 0 for r in absent),
            },
            "outcomes": {
                o: sum(r.outcome == o for r in every.values()) for o in {r.outcome for r in every.values()}
            },
        }
        if config.instructions_per_flight > 1:
            planners[planner]["per_instruction"] = per_instruction(list(rows.values()), config)
    summary = {
        "config": config.as_json(),
        "wall_s": round(wall_s, 1),
        "planners": planners,
        "missions": [r.to_json() for r in results],
    }
    summary["limits"] = limits_summary(results)
    for autopilot in ("px4", "ardupilot"):
        offset = f"{autopilot}_clock_offset_s"
        ready = [
            r.vehicle_clock_s["ready_s"] - r.info[offset]
            for r in results
            if "ready_s" in r.vehicle_clock_s and offset in r.info and r.info.get("warm_missions", 1) == 1
        ]
        if ready:  # SITL: simulated seconds from the bridge's start to the estimator seen ready by the client
            # (missions that started their autopilot: a warm one, reset between missions, is ready at once)
            summary[f"{autopilot}_ready_sim_s"] = {
                "mean": round(statistics.fmean(ready), 2),
                "max": round(max(ready), 2),
                "n": len(ready),
            }
    return summary


def per_instruction(results: list[MissionResult], config: BenchmarkConfig) -> dict[str, Any]:
    """Flights of several instructions, counted per instruction: centred (the instruction passed: centred
    within ε per truth on its own target, within the step budget), wrong-target centrings, not found,
    looked for again from the start; and centred by place in the flight (1st, 2nd, ...). An instruction
    its flight never reached (an error before it) counts as flown and not centred."""
    n = config.instructions_per_flight
    flown = [entry for r in results for entry in r.instructions]
    return {
        "instructions": len(results) * n,
        "centred": sum(entry["passed"] for entry in flown),
        "wrong_target": sum(entry["wrong_target"] for entry in flown),
        "not_found": sum(entry["outcome"] == "target_not_found" for entry in flown),
        "returned_to_start": sum(entry.get("returned_to_start", False) for entry in flown),
        "flights_all_centred": sum(
            len(r.instructions) == n and all(e["passed"] for e in r.instructions) for r in results
        ),
        "centred_by_place": [
            sum(1 for r in results for e in r.instructions if e["index"] == place and e["passed"])
            for place in range(1, n + 1)
        ],
    }


LOOP_TIMEOUT_SLACK_S = 10.0
"""The loop checks its timeout between steps: a run may end one move and one settle past it."""


def limits_summary(
    results: list[MissionResult], limits: SafetyLimits | None = None, timeout_s: float = 120.0
) -> dict[str, Any]:
    """Per simulator truth: missions over the speed limit or outside the geofence; the longest run; reports.

    The limits are `SafetyLimits`' defaults (what the missions fly under); the geofence box is
    around home, where the vehicle armed. Only simulated MAVLink vehicles report truth extremes.
    """
    limits = limits or SafetyLimits()
    fence = limits.geofence
    judged = [r for r in results if r.truth_extremes]
    too_fast = [
        r.name
        for r in judged
        if r.truth_extremes["max_horizontal_speed_m_s"] > limits.max_horizontal_speed_m_s
    ]
    outside = []
    if fence is not None:
        for r in judged:
            low, high = r.truth_extremes["min_ned_m"], r.truth_extremes["max_ned_m"]
            if (
                max(-low[0], high[0]) > fence.half_width_north_m
                or max(-low[1], high[1]) > fence.half_width_east_m
                or -low[2] > fence.max_up_m
            ):
                outside.append(r.name)
    return {
        "judged_by_truth": len(judged),
        "max_horizontal_speed_m_s": max(
            (r.truth_extremes["max_horizontal_speed_m_s"] for r in judged), default=None
        ),
        "over_speed_limit": too_fast,
        "outside_geofence": outside,
        "longest_run_wall_s": round(max((r.wall_s for r in results), default=0.0), 1),
        "over_timeout": [r.name for r in results if r.vehicle_s > timeout_s + LOOP_TIMEOUT_SLACK_S],
        "reports_incomplete": [],  # filled in by run_benchmark, which still has the folders
    }


def format_summary(summary: dict[str, Any]) -> str:
    """The side-by-side table."""

    def num(value: float | None, fmt: str) -> str:
        return "-" if value is None else format(value, fmt)

    cfg = summary["config"]
    base = parse_mission(cfg["base"], "the benchmark's base mission")
    second_choices_set = "max_second_choices" in cfg["base"].get("loop", {})
    lines = [
        f"{cfg['n']} missions per planner, seed {cfg['seed']}, vehicle {base.vehicle}, "
        f"budget {base.max_steps} steps, {'scaled' if base.loop.scale_moves else 'fixed'} moves, "
        + (f"at most {base.loop.max_second_choices} second choices, " if second_choices_set else "")
        + f"{summary['wall_s']:.0f} s",
    ]
    if base.targets > 1 or base.twins or cfg.get("absent"):
        corpus = cfg.get("instructions") or "heldout"
        lines.append(
            f"{base.targets} targets per scene{', with a twin' if base.twins else ''}; "
            f"instructions from the {corpus} phrases; "
            f"{100 * cfg.get('absent', 0.0):.0f}% name an absent target"
        )
        refused = {p: s["refused"] for p, s in summary["planners"].items() if s.get("refused")}
        if refused:
            lines.append(
                "refused before take-off (counted as failed): "
                + ", ".join(f"{p} {n}" for p, n in refused.items())
            )
    for key, who in (
        ("px4_ready_sim_s", "PX4 estimator ready (as seen by MAVSDK)"),
        ("ardupilot_ready_sim_s", "ArduPilot's EKF ready (as seen by the GUIDED backend)"),
    ):
        if key in summary:
            r = summary[key]
            lines.append(
                f"{who} {r['mean']:.1f} s simulated on average, {r['max']:.1f} s at most ({r['n']} missions)"
            )
    if base.faults.any:
        lines.append(f"injected faults: {base.faults.model_dump(mode='json', exclude_unset=True)}")
    limits = summary.get("limits")
    if limits and limits["judged_by_truth"]:
        n = {key: len(limits[key]) for key in ("over_speed_limit", "outside_geofence", "over_timeout")}
        lines.append(
            f"per truth ({limits['judged_by_truth']} missions): fastest "
            f"{limits['max_horizontal_speed_m_s']:.2f} m/s, {n['over_speed_limit']} over the speed limit, "
            f"{n['outside_geofence']} outside the geofence; longest run {limits['longest_run_wall_s']:.0f} s "
            f"wall, {n['over_timeout']} over the timeout, "
            f"{len(limits['reports_incomplete'])} reports incomplete"
        )
    if cfg.get("instructions_per_flight", 1) > 1:
        lines.append(
            f"{cfg['instructions_per_flight']} instructions per flight (one take-off), each on its own target"
        )
    any_absent = any(p.get("absent", {}).get("missions") for p in summary["planners"].values())
    any_vetoes = any(p.get("not_in_view", {}).get("reads") for p in summary["planners"].values())
    lines.append(
        f"{'planner':<8} {'success':>15} {'mean steps':>10} {'/oracle':>8} {'offset px mean/p95/max':>23} "
        f"{'refinement moves':>16} {'second choices':>14} {'overhead ms':>11} {'wrong target':>12}"
        + (f" {'absent: not found/wandered':>26}" if any_absent else "")
        + (f" {'planner: not in view (present/absent missions)':>47}" if any_vetoes else "")
    )
    for name, p in summary["planners"].items():
        refinements = f"{p['refinement_moves']} in {p['missions_with_refinement']}"
        seconds = f"{p.get('second_choice_moves', 0)} in {p.get('missions_with_second_choice', 0)}"
        offsets = "/".join(
            num(p[k], ".1f") for k in ("final_offset_px_mean", "final_offset_px_p95", "final_offset_px_max")
        )
        lines.append(
            f"{name:<8} {p['successes']:>5}/{p['missions']:<4} {100 * p['success_rate']:>5.1f}% "
            f"{num(p['mean_steps'], '.2f'):>10} {num(p['mean_steps_over_oracle'], '.2f'):>8} {offsets:>23} "
            f"{refinements:>16} {seconds:>14} {num(p['overhead_ms_mean'], '.1f'):>11} "
            f"{p.get('wrong_target', 0):>12}"
            + (f" {_absent_cell(p['absent']):>26}" if any_absent else "")
            + (f" {_not_in_view_cell(p['not_in_view']):>47}" if any_vetoes else "")
        )
    for name, p in summary["planners"].items():
        if "per_instruction" in p:
            lines.append(_per_instruction_line(name, p["per_instruction"]))
    return "\n".join(lines)


def _per_instruction_line(planner: str, counts: dict[str, Any]) -> str:
    """ "latent per instruction: 297/300 centred (99.0%), ..." """
    n = counts["instructions"]
    by_place = ", ".join(f"{k}/{n // len(counts['centred_by_place'])}" for k in counts["centred_by_place"])
    return (
        f"{planner} per instruction: {counts['centred']}/{n} centred "
        f"({100 * counts['centred'] / n if n else 0:.1f}%), {counts['wrong_target']} wrong target, "
        f"{counts['not_found']} not found, {counts.get('returned_to_start', 0)} looked for again from the "
        f"start; by place in the flight {by_place}; "
        f"{counts['flights_all_centred']} flights with every instruction centred"
    )


def _absent_cell(absent: dict[str, int]) -> str:
    """ "4/5, 1 moved": absent-target missions that ended target_not_found, and those that flew a move."""
    return f"{absent['not_found']}/{absent['missions']}, {absent['wandered']} moved"


def _not_in_view_cell(counts: dict[str, int]) -> str:
    """ "0/3": present and absent missions in which the planner said a detected target was not in view."""
    return f"{counts['present_missions']}/{counts['absent_missions']}"
