"""`ardupilot-sitl` as a vehicle kind of mission files and commands, checked before anything flies."""

from __future__ import annotations

from pathlib import Path

import pytest
from dronectl.fly_cmd import main as fly_main

from controller.benchmarks.mission_plan import BenchmarkConfig, benchmark_missions
from controller.missions.schema import MissionFileError, load_mission, parse_mission

REPO = Path(__file__).resolve().parents[1]


def test_an_ardupilot_sitl_mission_parses_and_its_section_goes_with_it_only() -> None:
    mission = load_mission(REPO / "missions" / "ardupilot" / "gauge_ardupilot_sitl.yaml")
    assert mission.vehicle == "ardupilot-sitl" and not mission.is_real
    assert mission.ardupilot.hold_mode == "BRAKE" and mission.ardupilot.keep_logs
    with pytest.raises(MissionFileError, match="ardupilot: only a 'ardupilot-sitl' mission runs it"):
        parse_mission({"name": "x", "vehicle": "px4-sitl", "ardupilot": {"speed": "max"}})
    with pytest.raises(MissionFileError, match=r"ardupilot\.instance: .*must be 0\.\.9"):
        parse_mission({"name": "x", "vehicle": "ardupilot-sitl", "ardupilot": {"instance": 12}})
    with pytest.raises(MissionFileError, match="autopilot: goes with a MAVLink URL"):
        parse_mission({"name": "x", "vehicle": "ardupilot-sitl", "autopilot": "px4"})
    url = {"vehicle": "udpin://0.0.0.0:14550", "camera": "rtsp://10.0.0.2/cam"}
    real = parse_mission({"name": "x", **url, "autopilot": "ardupilot"})
    assert real.is_real and real.autopilot == "ardupilot"
    wind = {"name": "x", "vehicle": "ardupilot-sitl", "wind": {"mean_enu_m_s": [0.5, 0, 0]}}
    assert parse_mission(wind).wind is not None  # the SITL world has wind, as px4-sitl's does


def test_benchmark_missions_carry_the_ardupilot_folder_and_speed() -> None:
    base = {"vehicle": "ardupilot-sitl", "ardupilot": {"dir": "/opt/ap", "speed": "max", "keep_logs": False}}
    config = BenchmarkConfig.of(base, n=2, planners=("latent",))
    missions = benchmark_missions(config, "latent", frozenset())
    assert [m.vehicle for m in missions] == ["ardupilot-sitl"] * 2
    assert missions[0].ardupilot.dir == "/opt/ap" and missions[0].ardupilot.speed == "max"
    assert not missions[0].ardupilot.keep_logs


def test_fly_names_a_missing_ardupilot_folder_before_anything_starts(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    missing, out = tmp_path / "nowhere", tmp_path / "r"
    assert fly_main(["--vehicle", "ardupilot-sitl", "--ardupilot", str(missing), "--out", str(out)]) == 2
    assert f"--ardupilot: {missing} is not a folder" in capsys.readouterr().err
    assert not out.exists()  # nothing started, no report
    assert fly_main(["--ardupilot-speed", "max"]) == 2  # the default mission flies in-process
    assert "--ardupilot and --ardupilot-speed go with --vehicle ardupilot-sitl" in capsys.readouterr().err
