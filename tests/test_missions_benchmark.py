"""The benchmark's missions (unseen, shared by every planner) and its side-by-side summary."""

from __future__ import annotations

from controller.benchmarks.missions import BenchmarkConfig, benchmark_missions, format_summary, summarise
from controller.missions.results import MissionResult


def row(index: int, planner: str, passed: bool, steps: int, refinements: int = 0) -> MissionResult:
    return MissionResult(
        name=f"bench-1-{index:04d}-{planner}", planner=planner, outcome="centred" if passed else "max_steps",
        passed=passed, failures=() if passed else ("outcome max_steps, expected centred",), steps=steps,
        moves=steps, epsilon_px=10.0, final_truth_offset_px=(3.0, -4.0 - index),
        final_detector_offset_px=None,
        wall_s=1.0, vehicle_s=5.0, overhead_ms_mean=20.0, refinement_moves=refinements,
    )  # fmt: skip


def test_every_planner_flies_the_same_scenes_and_skipped_seeds_are_replaced() -> None:
    config = BenchmarkConfig(n=5, seed=3, planners=("latent", "oracle"))
    latent = benchmark_missions(config, "latent", frozenset())
    oracle = benchmark_missions(config, "oracle", frozenset())
    assert [m.scene.seed for m in latent] == [m.scene.seed for m in oracle]
    assert [m.start for m in latent] == [m.start for m in oracle]
    skipped = latent[1].scene.seed
    again = benchmark_missions(config, "latent", frozenset({skipped}))
    assert skipped not in [m.scene.seed for m in again] and len(again) == 5
    assert latent[0].loop.scale_moves is True
    fixed = BenchmarkConfig.of({"loop": {"scale_moves": False}}, n=1, seed=3)
    assert benchmark_missions(fixed, "random", frozenset())[0].loop.scale_moves is False


def test_a_site_benchmark_flies_one_scene_from_starts_drawn_in_the_ranges_given() -> None:
    config = BenchmarkConfig(n=4, seed=3, planners=("latent",), scene_seed=0, distance_m=(1.6, 2.4))
    missions = benchmark_missions(config, "latent", frozenset())
    assert {m.scene.seed for m in missions} == {0}  # the site
    starts = [m.start.random for m in missions]
    assert len({s.seed for s in starts}) == 4 and all(s.distance_m == (1.6, 2.4) for s in starts)
    unseen = benchmark_missions(BenchmarkConfig(n=4, seed=3, planners=("latent",)), "latent", frozenset())
    assert [m.start.random.seed for m in unseen] == [s.seed for s in starts]  # the same starts' draws


def test_summary_counts_successes_steps_over_the_oracle_and_refinement_moves() -> None:
    config = BenchmarkConfig(n=2, seed=1, planners=("latent", "oracle"))
    results = [
        row(0, "latent", True, 3, refinements=1), row(1, "latent", False, 20),
        row(0, "oracle", True, 2, refinements=2), row(1, "oracle", True, 2),
    ]  # fmt: skip
    summary = summarise(config, results, wall_s=4.0)
    latent = summary["planners"]["latent"]
    assert latent["successes"] == 1 and latent["success_rate"] == 0.5
    assert latent["mean_steps_over_oracle"] == 1.5  # mission 0 only: both solved it
    assert latent["refinement_moves"] == 1 and latent["missions_with_refinement"] == 1
    assert summary["planners"]["oracle"]["refinement_moves"] == 2
    assert latent["final_offset_px_max"] == 5.0
    table = format_summary(summary)
    assert "refinement moves" in table
    assert "1 in 1" in table and "2 in 1" in table
