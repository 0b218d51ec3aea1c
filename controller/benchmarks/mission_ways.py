"""The same missions flown each way (in-process, sim-mavlink, PX4 SITL, ArduPilot SITL) in one run: where
the time goes, and each way's wall time as a ratio of the in-process one's.

Every way flies the same missions (`controller.benchmarks.mission_plan`: same seed, same scenes, starts
and planners) through `controller.benchmarks.missions.run_benchmark`, one way after another in this one
process, so the ratios compare runs under the same load. Per way: the wall time (worker start and model
loading included, as a user waits for them), success and steps, and each mission's phases
(`controller.missions.phases.PHASES` and the loop's parts), as means per mission; the vehicle's own clock
(a simulator's simulated time) for readiness, takeoff and landing.
"""

from __future__ import annotations

import os
import statistics
from collections.abc import Mapping
from typing import Any

from controller.benchmarks.mission_plan import BenchmarkConfig
from controller.benchmarks.missions import run_benchmark
from controller.missions.phases import LOOP_PARTS, PHASES
from controller.missions.schema import SIM

_SIM_CLOCK_SPANS = (
    ("ready", "connected_s", "ready_s"),
    ("takeoff", "ready_s", "offboard_s"),
    ("loop", "offboard_s", "loop_end_s"),
    ("landing", "loop_end_s", "landed_s"),
)
"""Spans of the vehicle's clock (simulated seconds on a simulator) between two milestones."""


def _mean(values: list[float]) -> float | None:
    return round(statistics.fmean(values), 4) if values else None


def way_summary(summary: dict[str, Any]) -> dict[str, Any]:
    """One way's figures from its benchmark summary: wall, outcomes, mean phases per mission."""
    missions = summary["missions"]
    phases = {
        name: _mean([m["phases_s"][name] for m in missions if name in m.get("phases_s", {})])
        for name in (*PHASES, *LOOP_PARTS)
    }
    vehicle_clock = {
        name: _mean(
            [
                m["vehicle_clock_s"][end] - m["vehicle_clock_s"][begin]
                for m in missions
                if begin in m["vehicle_clock_s"] and end in m["vehicle_clock_s"]
            ]
        )
        for name, begin, end in _SIM_CLOCK_SPANS
    }
    planners = {
        name: {
            "successes": p["successes"],
            "missions": p["missions"],
            "mean_steps": p["mean_steps"],
            "outcomes": p["outcomes"],
        }
        for name, p in summary["planners"].items()
    }
    return {
        "wall_s": summary["wall_s"],
        "missions": len(missions),
        "mission_wall_s_mean": _mean([sum(m["phases_s"].get(p, 0.0) for p in PHASES) for m in missions]),
        "phases_s_mean": phases,
        "vehicle_clock_s_mean": vehicle_clock,
        "planners": planners,
        "limits": summary["limits"],
        "errors": [m["error"] for m in missions if m.get("error")][:5],
    }


def run_ways(configs: Mapping[str, BenchmarkConfig]) -> dict[str, Any]:
    """Fly each way's benchmark in turn (`configs`: way → its benchmark, the same missions each) and
    return every way's figures with its wall time over the in-process way's (or the first way's)."""
    ways: dict[str, Any] = {}
    load_before = os.getloadavg()
    for way, config in configs.items():
        load = os.getloadavg()
        ways[way] = {**way_summary(run_benchmark(config)), "load_average_before": [round(v, 2) for v in load]}
    reference = SIM if SIM in ways else next(iter(ways))
    for figures in ways.values():
        figures["ratio"] = round(figures["wall_s"] / ways[reference]["wall_s"], 2)
    first = next(iter(configs.values()))
    return {
        "n": first.n,
        "seed": first.seed,
        "planners": list(first.planners),
        "parallel": first.parallel,
        "reference": reference,
        "load_average_before": [round(v, 2) for v in load_before],
        "load_average_after": [round(v, 2) for v in os.getloadavg()],
        "cpus": os.cpu_count(),
        "ways": ways,
    }


def format_ways(report: dict[str, Any]) -> str:
    """The ratios and the phases per way as a table."""

    def num(value: float | None, fmt: str = ".2f") -> str:
        return "-" if value is None else format(value, fmt)

    load = " ".join(f"{v:.2f}" for v in report["load_average_before"])
    load_after = " ".join(f"{v:.2f}" for v in report["load_average_after"])
    lines = [
        f"{report['n']} missions per planner each way, seed {report['seed']}, planners "
        f"{','.join(report['planners'])}, parallel {report['parallel']}; load average {load} before, "
        f"{load_after} after ({report['cpus']} CPUs)",
        f"{'way':<15} {'wall s':>7} {'ratio':>6} {'success':>8} {'steps':>6}   mean s per mission: "
        + " ".join(f"{p:>8}" for p in (*PHASES, *LOOP_PARTS)),
    ]
    for way, w in report["ways"].items():
        successes = sum(p["successes"] for p in w["planners"].values())
        total = sum(p["missions"] for p in w["planners"].values())
        steps = [p["mean_steps"] for p in w["planners"].values() if p["mean_steps"] is not None]
        lines.append(
            f"{way:<15} {w['wall_s']:>7.1f} {w['ratio']:>6.2f} {f'{successes}/{total}':>8} "
            f"{num(statistics.fmean(steps) if steps else None):>6}   {'':>19}"
            + " ".join(f"{num(w['phases_s_mean'][p]):>8}" for p in (*PHASES, *LOOP_PARTS))
        )
    lines.append("vehicle clock (simulated s per mission): " + "; ".join(
        f"{way} " + ", ".join(f"{k} {num(v)}" for k, v in w["vehicle_clock_s_mean"].items())
        for way, w in report["ways"].items()
    ))  # fmt: skip
    for way, w in report["ways"].items():
        if w["errors"]:
            lines.append(f"{way}: errors, e.g. {w['errors'][0]}")
    return "\n".join(lines)
