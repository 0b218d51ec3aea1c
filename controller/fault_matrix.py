"""The fault matrix: the same randomised missions flown under each injected fault, one row per fault.

Every row is a `benchmark-missions` run (same scenes and starts, seeded) with one fault
set; the table says how many missions were centred, the worst final offset per truth,
the longest run, and how the others ended (a mission that cannot succeed, because the
camera or the vehicle dies, must still end safely, with a complete report). Written as
markdown by `dronectl fault-matrix` (docs/reliability.md is its output).
"""

from __future__ import annotations

import collections
import logging
from dataclasses import dataclass, replace
from typing import Any

from controller.benchmark_missions import BenchmarkConfig, run_benchmark

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class FaultRow:
    """One fault: a name, the `faults:` mapping, and the benchmark options that give it."""

    name: str
    faults: dict[str, Any] | None
    options: str


DEFAULT_ROWS: tuple[FaultRow, ...] = (
    FaultRow("none (baseline)", None, ""),
    FaultRow(
        "link: 20 % loss, 200 ms latency",
        {"link": {"loss": 0.2, "latency_ms": 200.0}},
        "--link-loss 0.2 --link-latency-ms 200",
    ),
    FaultRow(
        "link: 20 % loss, 200 ± 50 ms, 2 % duplicated, 5 % reordered",
        {"link": {"loss": 0.2, "latency_ms": 200.0, "jitter_ms": 50.0, "duplicate": 0.02, "reorder": 0.05}},
        "--link-loss 0.2 --link-latency-ms 200 --link-jitter-ms 50 --link-duplicate 0.02 --link-reorder 0.05",
    ),
    FaultRow("camera: 20 % of frames dropped", {"camera": {"drop": 0.2}}, "--frame-drop 0.2"),
    FaultRow(
        "camera: picture frozen for 3 s at 16 s",
        {"camera": {"freeze_at_s": 16.0, "freeze_for_s": 3.0}},
        "--camera-freeze-at-s 16 --camera-freeze-for-s 3",
    ),
    FaultRow("camera: stream dies at 16 s", {"camera": {"dies_at_s": 16.0}}, "--camera-dies-at-s 16"),
    FaultRow("wind: gusts of 1.5 m/s (std)", {"gust_m_s": 1.5}, "--gust-m-s 1.5"),
    FaultRow("vehicle dies at 16 s", {"vehicle_dies_at_s": 16.0}, "--vehicle-dies-at-s 16"),
)


def run_fault_matrix(
    base: BenchmarkConfig, rows: tuple[FaultRow, ...] = DEFAULT_ROWS
) -> list[dict[str, Any]]:
    """Fly `base` (one planner) under each row's fault; one summary row each."""
    planner = base.planners[0]
    out = []
    for row in rows:
        log.info("fault matrix: %s", row.name)
        summary = run_benchmark(replace(base, faults=row.faults, planners=(planner,)))
        missions = summary["missions"]
        rows_ok = [m for m in missions if m["passed"]]
        offsets = [m["final_truth_error_px"] for m in missions if m["final_truth_error_px"] is not None]
        ended = collections.Counter(_how_it_ended(m) for m in missions if not m["passed"])
        limits = summary["limits"]
        out.append(
            {
                "fault": row.name,
                "command": _command(base, planner, row),
                "missions": len(missions),
                "centred": len(rows_ok),
                "worst_final_offset_px": round(max(offsets), 1) if offsets else None,
                "longest_run_wall_s": limits["longest_run_wall_s"],
                "others_ended": dict(ended),
                "over_speed_limit": len(limits["over_speed_limit"]),
                "outside_geofence": len(limits["outside_geofence"]),
                "reports_incomplete": len(limits["reports_incomplete"]),
                "wall_s": summary["wall_s"],
            }
        )
    return out


def _how_it_ended(mission: dict[str, Any]) -> str:
    error = mission.get("error") or ""
    kind = error.split(":", 1)[0] if error else ""
    return f"{mission['outcome']} ({kind})" if kind else mission["outcome"]


def _command(base: BenchmarkConfig, planner: str, row: FaultRow) -> str:
    parts = [
        "dronectl benchmark-missions", f"--vehicle {base.vehicle}", f"--n {base.n}", f"--seed {base.seed}",
        f"--planner {planner}", f"--parallel {base.parallel}",
    ]  # fmt: skip
    return " ".join(parts + ([row.options] if row.options else []))


def format_markdown(rows: list[dict[str, Any]], base: BenchmarkConfig) -> str:
    """The matrix as a markdown table, with the conditions it was measured under."""
    lines = [
        f"Vehicle `{base.vehicle}`, planner `{base.planners[0]}`, {base.n} randomised missions per row "
        f"(seed {base.seed}, unseen scenes), `--parallel {base.parallel}`.",
        "",
        "| fault | command | missions | centred | worst final offset (px, truth) | longest run (s) "
        "| the others ended | over speed limit / outside geofence (truth) | reports incomplete |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in rows:
        ended = ", ".join(f"{k}: {v}" for k, v in sorted(r["others_ended"].items())) or "-"
        offset = "-" if r["worst_final_offset_px"] is None else f"{r['worst_final_offset_px']:.1f}"
        share = 100 * r["centred"] / max(1, r["missions"])
        lines.append(
            f"| {r['fault']} | `{r['command']}` | {r['missions']} | {r['centred']} "
            f"({share:.0f} %) | {offset} | {r['longest_run_wall_s']:.0f} "
            f"| {ended} | {r['over_speed_limit']} / {r['outside_geofence']} | {r['reports_incomplete']} |"
        )
    return "\n".join(lines) + "\n"
