"""`dronectl fly --rerun FILE.rrd`: the recording read back (Rerun's own reader and `rerun rrd verify`)
holds every step the report holds, on simulated time; an existing file is refused before anything
flies; a recording that fails never costs the flight or its report."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pyarrow as pa
import pytest
from rerun.chunk import RrdReader

from controller.missions.rerun_log import RerunFileError, check_rerun_path
from controller.missions.runner import run_mission
from controller.missions.schema import parse_mission

MISSION = {
    "name": "rerun-check",
    "scene": {"seed": 31337},
    "target_kind": "gauge",
    "start": {"right_m": 0.5, "up_m": -0.3, "distance_m": 2.0, "yaw_deg": 0},
    "vehicle": "sim",
    "planner": "latent",
}


def _columns(path: Path) -> dict[str, dict[str, list]]:
    """entity path → column name → values, over every chunk of the file's recording."""
    out: dict[str, dict[str, list]] = {}
    for chunk in RrdReader(path).stream():
        batch = chunk.to_record_batch()
        columns = out.setdefault(str(chunk.entity_path).lstrip("/"), {})
        for name in batch.schema.names:
            column = batch.column(name)
            if pa.types.is_temporal(column.type):  # log_time / sim_time: nanoseconds as integers
                column = column.cast(pa.int64())
            columns.setdefault(name, []).extend(column.to_pylist())
    return out


def test_a_recorded_mission_reads_back_with_every_step_on_simulated_time(tmp_path: Path) -> None:
    rrd = tmp_path / "flight.rrd"
    result = run_mission(parse_mission(MISSION), tmp_path / "report", media=False, rerun_path=rrd)
    assert result.outcome == "centred" and result.steps >= 1
    report = json.loads((tmp_path / "report" / "report.json").read_text())
    steps = report["instructions"][0]["records"]
    data = _columns(rrd)

    images = data["camera/image"]
    assert images["step"] == [s["index"] for s in steps]
    sim_times = [ns / 1e9 for ns in images["sim_time"]]
    assert sim_times == pytest.approx([s["vehicle_time_s"] for s in steps], abs=1e-3)  # the report keeps ms

    first = steps[0]
    for i, name in enumerate(
        (
            "left_up",
            "left_none",
            "left_down",
            "none_up",
            "none_none",
            "none_down",
            "right_up",
            "right_none",
            "right_down",
        )
    ):
        recorded = data[f"planner/distance/{name}"]["Scalars:scalars"][0][0]
        assert recorded == pytest.approx(first["distances"][i], abs=1e-5)
    moved = [s for s in steps if s["move"] is not None]
    commanded = [v[0] for v in data["move/commanded/right_m"]["Scalars:scalars"]]
    assert commanded == pytest.approx([s["move"]["commanded_m"]["right_m"] for s in moved], abs=1e-4)
    flown = [v[0] for v in data["move/flown/right_m"]["Scalars:scalars"]]
    assert flown == pytest.approx([s["move"]["flown_m"]["right_m"] for s in moved], abs=1e-3)
    truth_du = [v[0] for v in data["offset/truth/du"]["Scalars:scalars"]]
    assert truth_du == pytest.approx([s["truth_offset_px"][0] for s in steps], abs=1e-3)
    assert len(data["camera/image/detection"]["step"]) == len(steps)
    assert len(data["world/trajectory"]["step"]) == len(steps) + len(
        moved
    )  # a pose per step and per move end
    assert "camera/image/epsilon" in data and "mission" in data

    cli = shutil.which("rerun")
    if cli is not None:  # the viewer's own loader: the file opens
        verified = subprocess.run(
            [cli, "rrd", "verify", str(rrd)], capture_output=True, text=True, timeout=120
        )
        assert verified.returncode == 0, verified.stderr[-2000:]


def test_an_existing_recording_is_refused_before_anything_flies(tmp_path: Path) -> None:
    rrd = tmp_path / "old.rrd"
    rrd.write_bytes(b"earlier flight")
    with pytest.raises(RerunFileError, match="never overwritten"):
        run_mission(parse_mission(MISSION), tmp_path / "report", media=False, rerun_path=rrd)
    assert rrd.read_bytes() == b"earlier flight"
    report = json.loads((tmp_path / "report" / "report.json").read_text())
    assert "never overwritten" in report["error"] and report["instructions"] == []
    with pytest.raises(RerunFileError, match=r"\.rrd"):
        check_rerun_path(tmp_path / "flight.txt")
    with pytest.raises(RerunFileError, match="does not exist"):
        check_rerun_path(tmp_path / "missing" / "flight.rrd")


def test_a_failing_recording_never_costs_the_flight(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import rerun as rr

    def broken_image(*args, **kwargs):
        raise OSError("disk full (injected)")

    monkeypatch.setattr(rr, "Image", broken_image)
    rrd = tmp_path / "flight.rrd"
    result = run_mission(parse_mission(MISSION), tmp_path / "report", media=False, rerun_path=rrd)
    assert result.outcome == "centred" and result.error is None
    report = json.loads((tmp_path / "report" / "report.json").read_text())
    assert report["status"] == "finished" and len(report["instructions"][0]["records"]) == result.steps + 1


def test_benchmark_missions_record_each_mission_in_its_report_folder(tmp_path: Path) -> None:
    from controller.benchmarks.missions import MISSION_RRD, BenchmarkConfig, run_benchmark

    summary = run_benchmark(
        BenchmarkConfig(n=2, seed=3, planners=("classic",), rerun=True), report_dir=tmp_path / "b"
    )
    folders = sorted((tmp_path / "b").iterdir())
    assert len(folders) == 2 and summary["planners"]["classic"]["missions"] == 2
    for folder in folders:
        steps = json.loads((folder / "report.json").read_text())["instructions"][0]["records"]
        assert _columns(folder / MISSION_RRD)["camera/image"]["step"] == [s["index"] for s in steps]


def test_each_instruction_of_a_flight_is_visible_in_the_recording(tmp_path: Path) -> None:
    """Three instructions, one flight (fakes): each instruction's text on its own `instruction` time, every
    frame on the instruction it served, the `step` time counted over the whole flight."""
    from fake_vehicle import FakeVehicle
    from mission_fakes import FakeMultiTargetDetector
    from test_flight_session import LIMITS, WALL, kit_for

    from controller.missions.runner import fly_kit

    vehicle = FakeVehicle.at_pose(east_m=-0.3, up_m=0.2)
    mission = parse_mission(
        {
            "name": "three",
            "planner": "classic",
            "instructions": ["the gauge", "the red valve", "the switch box"],
        }
    )
    kit = kit_for(vehicle, FakeMultiTargetDetector(vehicle, WALL))
    result = fly_kit(kit, mission, tmp_path, LIMITS, media=False, rerun_path=tmp_path / "flight.rrd")
    assert result.passed, result.failures
    data = _columns(tmp_path / "flight.rrd")
    said = sorted(zip(data["instruction"]["instruction"], data["instruction"]["TextLog:text"], strict=True))
    assert said == [(1, ["1: the gauge"]), (2, ["2: the red valve"]), (3, ["3: the switch box"])]
    report = json.loads((tmp_path / "report.json").read_text())
    served = [entry["index"] for entry in report["instructions"] for _ in entry["records"]]
    images = data["camera/image"]  # chunks come back in no fixed order: by step
    assert sorted(zip(images["step"], images["instruction"], strict=True)) == list(enumerate(served))
