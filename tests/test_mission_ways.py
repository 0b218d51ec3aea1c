"""`dronectl bench missions`: a mission's phases, and the same missions flown each way with the ratios."""

from __future__ import annotations

from controller.benchmarks.mission_plan import BenchmarkConfig
from controller.benchmarks.mission_ways import format_ways, run_ways
from controller.missions.phases import LOOP_PARTS, PHASES, flight_phases
from controller.planning.loop_records import StepTiming


def test_phases_run_from_milestone_to_milestone_and_a_missed_one_goes_to_the_next() -> None:
    wall = {"connected_s": 0.5, "ready_s": 1.5, "offboard_s": 4.0, "loop_end_s": 6.0, "landed_s": 9.0}
    phases = flight_phases(wall, [])
    assert phases["connect"] == 0.5 and phases["ready"] == 1.0 and phases["takeoff"] == 2.5
    assert phases["loop"] == 2.0 and phases["landing"] == 3.0
    aborted = flight_phases({"connected_s": 0.5, "offboard_s": 4.0}, [])  # readiness never noted
    assert "ready" not in aborted and aborted["takeoff"] == 3.5 and "landing" not in aborted


def test_loop_parts_add_up_the_steps_timings() -> None:
    phases = flight_phases({}, [StepTiming(0.1, 0.02, 0.03, 0.5, 0.7)] * 3)
    assert abs(phases["renders"] - 0.3) < 1e-9
    assert abs(phases["decisions"] - 0.15) < 1e-9
    assert abs(phases["moves"] - 1.5) < 1e-9


def test_each_way_reports_its_phases_and_its_ratio_to_the_in_process_one() -> None:
    config = BenchmarkConfig.of({"detector": "truth"}, n=1, seed=5, planners=("oracle",))
    report = run_ways({"sim": config})
    sim = report["ways"]["sim"]
    assert report["reference"] == "sim" and sim["ratio"] == 1.0
    assert sim["planners"]["oracle"]["missions"] == 1
    phases = sim["phases_s_mean"]
    assert set(phases) == {*PHASES, *LOOP_PARTS}
    assert all(phases[p] is not None and phases[p] >= 0.0 for p in PHASES)
    assert phases["moves"] > 0.0 and phases["moves"] <= phases["loop"]
    # The phases are the whole mission: together no longer than the benchmark's wall time.
    assert 0.0 < sim["mission_wall_s_mean"] <= sim["wall_s"] + 0.1
    assert sim["vehicle_clock_s_mean"]["takeoff"] > 0.0  # simulated seconds of the climb
    table = format_ways(report)
    assert "sim" in table and "takeoff" in table and "load average" in table
